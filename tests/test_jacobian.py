"""boucwen._core.simulate_extended_with_jacobian: the output and its Jacobian in one pass,
as the fits use it (the columns in the order of boucwen.effects.Layout, whose β and γ
columns the layout turns into β + γ and β − γ)."""

import numpy as np
import pytest

from boucwen import EffectSet, Params, simulate_extended
from boucwen._core import simulate_extended_with_jacobian
from boucwen.effects.fit import Layout

DT = 5e-4
T = np.arange(1200) * DT
U = 50 + 40 * np.sin(2 * np.pi * 5 * T) + 6 * np.cos(2 * np.pi * 13 * T)
P = Params.paper_1hz()
EFFECTS = [
    EffectSet(),
    EffectSet(
        creep={"tau_s": [0.01, 0.2], "gain_um_per_v": [0.01, 0.02]},
        input_lag={"fc_hz": 40.0},
        gain_drift={"rate_per_s": 0.05},
        electrostriction={"epsilon_per_um": 0.004},
        drift={"rate_um_per_s": 0.3},
        delay={"samples": 2},
        pickup={"line_hz": 50.0, "sin_um": [0.1, 0.02], "cos_um": [-0.05, 0.01]},
    ),
    EffectSet(
        resonance={"fn_hz": 120.0, "zeta": 0.2},
        resonance2={"fn_hz": 300.0, "zeta": 0.5},
        saturation={"min_um": 4.0, "max_um": 14.0},
    ),
]


@pytest.mark.parametrize("effects", EFFECTS, ids=lambda e: "+".join(e.names) or "base")
def test_every_column_matches_a_central_difference_of_the_simulator(effects):
    layout = Layout.of(effects, DT, DT * (U.size - 1))
    v = layout.pack(P, effects, 0.1)
    x, core_jac = simulate_extended_with_jacobian(P, effects, U, DT, 0.1)
    np.testing.assert_array_equal(x, simulate_extended(P, effects, U, DT, 0.1))
    assert core_jac.shape == (U.size, len(layout.labels()))
    # The layout's (β + γ, β − γ) give back β and γ to the last bits, and its Jacobian is
    # the core's with the columns of β and γ turned into those of β ± γ.
    x_layout, jac = layout.simulate_with_jacobian(v, U, DT)
    np.testing.assert_allclose(x_layout, x, rtol=1e-13, atol=0)
    np.testing.assert_allclose(np.delete(jac, [3, 4], axis=1), np.delete(core_jac, [3, 4], axis=1), rtol=1e-9)
    np.testing.assert_allclose(jac[:, 3], 0.5 * (core_jac[:, 3] + core_jac[:, 4]), rtol=1e-9, atol=1e-12)
    for j, label in enumerate(layout.labels()):
        step = 1e-6 * max(abs(v[j]), 1e-2)
        shifted = [layout.simulate(v + d * np.eye(v.size)[j], U, DT) for d in (step, -step)]
        fd = (shifted[0] - shifted[1]) / (2 * step)
        # 1e-5 of the column's largest entry: the central difference's truncation
        # (~1e-12) and rounding (~1e-9 µm per unit) errors are far below it; a wrong
        # derivative is off by its own size (see rust/effects/jacobian.rs).
        largest = np.max(np.abs(jac[:, j]))
        assert largest > 0, label
        assert np.max(np.abs(fd - jac[:, j])) <= 1e-5 * largest, label


def test_bad_input_raises_value_error():
    with pytest.raises(ValueError, match="u"):
        simulate_extended_with_jacobian(P, None, [0.0, np.nan], DT, 0.0)
    with pytest.raises(ValueError, match="dt"):
        simulate_extended_with_jacobian(P, None, U, -1.0, 0.0)
    with pytest.raises(ValueError, match="h0"):
        simulate_extended_with_jacobian(P, None, U, DT, np.inf)
    with pytest.raises(ValueError, match="Nyquist"):
        simulate_extended_with_jacobian(P, EffectSet(resonance={"fn_hz": 1500.0, "zeta": 0.1}), U, DT, 0.0)
