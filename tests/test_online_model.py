"""Online identification yields a better *model*, measured as a model (period-ahead).

On the simulated bench (:mod:`boucwen.plant`): started from the traditional offline fit,
the default online method (``Identifier(dt, init)``, moving horizon) stays within 5 % of
the fit on a record that does not change, and beats it where the input frequency moves
away from the one it was fitted on.
"""

from __future__ import annotations

import numpy as np
import pytest

import boucwen
from boucwen import evaluation, plant

DT = plant.DEFAULT_DT


def test_starts_where_it_is_given_and_stays_there():
    # 1 Hz only, the fit on the first 3 s: each period's open-loop error of the online
    # model, frozen at the period's start, against the fixed fit's on the same period.
    _, u, segments = plant.paper_input(DT, ((1.0, 6.0),))
    rec = plant.measure(u, DT, seed=3)
    fit = boucwen.fit(rec.u[:30_000], rec.x[:30_000], DT)
    assert fit.params.n < 1.0  # the best fit here has n < 1: it must be used as given
    ident = boucwen.Identifier(DT, fit.params, fit.h0)
    assert ident.params == fit.params
    x_fit, _ = boucwen.simulate(fit.params, rec.u, DT, fit.h0)
    err = np.abs(rec.x - np.asarray(x_fit))
    period = evaluation.period_samples(1.0, DT)
    fixed = [float(err[k : k + period].max()) for k in range(0, u.size - period + 1, period)]
    _, per_period, _ = evaluation.period_ahead(ident, rec.u, rec.x, DT, segments)
    online = per_period["1"][: len(fixed)]
    ratios = [a / b for a, b in zip(online, fixed)]
    assert max(ratios) <= 1.05, ratios


@pytest.fixture(scope="module")
def bench() -> tuple[dict[str, float], dict[str, float]]:
    _, u, segments = plant.paper_input(DT, ((1.0, 3.0), (10.0, 0.3), (100.0, 0.03), (200.0, 0.1)))
    rec = plant.measure(u, DT, seed=0)
    _, lo, hi = segments[0]
    fit = boucwen.fit(rec.u[lo:hi], rec.x[lo:hi], DT)
    traditional = evaluation.fixed_model(fit.params, fit.h0, rec.u, rec.x, DT, segments)
    online, _, _ = evaluation.period_ahead(boucwen.Identifier(DT, fit.params, fit.h0), rec.u, rec.x, DT, segments)
    return online, traditional


def test_a_better_model_than_the_offline_fit_once_the_frequency_moves(bench):
    online, traditional = bench
    assert online["1"] <= 1.05 * traditional["1"], (online, traditional)
    for f in ("10", "100", "200"):
        assert online[f] < traditional[f], (f, online, traditional)


def test_the_default_identifies_the_amplifier_lag_and_forecasts_with_it():
    # The bench's amplifier has a 650 Hz corner; fast parts of the input reveal it.
    _, u, _ = plant.paper_input(DT, ((1.0, 1.0), (100.0, 0.05), (200.0, 0.1)))
    rec = plant.measure(u, DT, seed=2)
    fit = boucwen.fit(rec.u[:10_000], rec.x[:10_000], DT)
    ident = boucwen.Identifier(DT, fit.params, fit.h0)
    assert ident.effects is not None
    assert ident.effects.to_dict()["input_lag"]["fc_hz"] == pytest.approx(0.3 / DT)
    base = boucwen.Identifier.horizon(DT, fit.params, fit.h0)
    assert base.effects == boucwen.EffectSet()
    k0 = u.size - evaluation.period_samples(200.0, DT)
    ident.push_many(rec.u[:k0], rec.x[:k0])
    base.push_many(rec.u[:k0], rec.x[:k0])
    fc = ident.effects.to_dict()["input_lag"]["fc_hz"]
    assert fc == pytest.approx(650.0, rel=0.1)
    state = (ident.params, ident.h, ident.effects)
    ahead = ident.forecast(rec.u[k0:])
    assert (ident.params, ident.h, ident.effects) == state  # forecasting changes nothing
    with_lag = float(np.max(np.abs(rec.x[k0:] - ahead)))
    without = float(np.max(np.abs(rec.x[k0:] - base.forecast(rec.u[k0:]))))
    assert with_lag < 0.5 * without, (with_lag, without)
    with pytest.raises(ValueError, match="u"):
        ident.forecast([1.0, float("nan")])
