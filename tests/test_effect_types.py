"""Typed effects: the classes, their EffectSet/dict/JSON round trips, and the extended
fit's unknowns, bounds, scales and starting values, pinned to their values."""

import dataclasses
import json
import math
import pickle

import numpy as np
import pytest

import boucwen
import boucwen.lsq
from boucwen import (
    BetweenSamples,
    Creep,
    Delay,
    Drift,
    EffectSet,
    Electrostriction,
    GainDrift,
    InputLag,
    Params,
    Pickup,
    Resonance,
    Resonance2,
    Saturation,
    effect_set,
    effects_of,
    simulate,
)
from boucwen.effects import (
    EFFECTS,
    VOCABULARY,
    Context,
    Layout,
    Start,
    candidate_starts,
    fit_extended_record,
    from_json,
    to_json,
)
from boucwen.effects.electrostriction import STROKE_BENDS
from boucwen.effects.resonance import PEAK_ZETAS, residual_peaks_hz
from boucwen.fit import record_delta_limit
from boucwen.record import validate_record
from conftest import EVERY_EFFECT, WHOLE_VOCABULARY

P = Params.paper_1hz()
DT = 1e-3
INF = math.inf
#: The effects whose layout and starts are pinned; ALL: the whole vocabulary.
PINNED = EVERY_EFFECT
ALL = WHOLE_VOCABULARY
LABELS = [
    *["kv", "x0", "A", "beta_plus_gamma", "beta_minus_gamma", "n", "delta", "h0"],
    *["creep.gain[0]", "creep.gain[1]", "input_lag.ln_fc", "resonance.ln_fn", "resonance.ln_zeta", "drift.rate"],
]
#: β and γ enter as β + γ and β − γ (the admissible region, bounded below by 0).
V0 = [0.19, 0.015, -0.072, 0.02 + -0.019, 0.02 - -0.019, 1.52, 0.0075, 0.1, 0.003, 0.004]
V0 += [4.382026634673881, 5.0106352940962555, -2.3025850929940455, 0.2]
LOWER = [-INF] * 3 + [0.0, 0.0, 0.2] + [-INF] * 4
LOWER += [-1.0986122886681098, -0.40546510810816444, -6.907755278982137, -INF]
UPPER = [INF] * 5 + [6.0] + [INF] * 4 + [9.210340371976184, 6.1092475827643655, 0.0, INF]
TYPICAL = [0.19, 13.7, 0.1522222222222222, 0.02 + -0.019, 0.02 - -0.019, 1.52, 0.0075, 0.13699999999999998]
TYPICAL_EFFECTS = [4.382026634673881, 5.0106352940962555, 2.3025850929940455, 0.2]


def _record():
    t = np.arange(3001) * DT
    u = 50 + 45 * np.sin(2 * np.pi * 2 * t)
    return validate_record(u, 0.15 * u + 0.1 * np.sin(2 * np.pi * 2 * t), DT)


def test_layout_of_every_effect_is_unchanged():
    e = EffectSet(**PINNED)
    lay = Layout.of(e, DT, 3.0)
    assert lay.labels() == LABELS
    assert lay.pack(P, e, 0.1).tolist() == V0
    lo, hi = lay.bounds()
    assert lo.tolist() == LOWER and hi.tolist() == UPPER


class _Stop(Exception):
    pass


@pytest.mark.parametrize("kv", [0.19, -0.19])
def test_fit_starts_from_the_same_point_bounds_and_scales(monkeypatch, kv):
    # The creep gains share the sign of kv: bounded at 0 for the optimiser.
    seen = {}

    def solve(self, z0, lower, upper, *, x_scale, tol, max_nfev, **options):
        seen.update(z0=z0, lower=lower, upper=upper, x_scale=x_scale)
        raise _Stop

    monkeypatch.setattr(boucwen.lsq.OutputErrorProblem, "solve", solve)
    with pytest.raises(_Stop):
        fit_extended_record(_record(), P.replace(kv=kv), EffectSet(**PINNED), 0.1)
    gains = [0.003, 0.004] if kv > 0 else [-1e-09, -1e-09]
    assert seen["z0"].tolist() == [kv, *V0[1:8], *gains, *V0[10:]]
    sign_lo, sign_hi = ([0.0, 0.0], [INF, INF]) if kv > 0 else ([-INF, -INF], [0.0, 0.0])
    # On a record, δ is kept within the record's limit (boucwen.fit.record_delta_limit).
    limit = record_delta_limit(_record())
    assert 0.0 < limit < INF
    lower, upper = [*LOWER[:6], -limit, *LOWER[7:8]], [*UPPER[:6], limit, *UPPER[7:8]]
    assert seen["lower"].tolist() == [*lower, *sign_lo, *LOWER[10:]]
    assert seen["upper"].tolist() == [*upper, *sign_hi, *UPPER[10:]]
    gain_scales = gains if kv > 0 else [0.0015222222222222221] * 2
    assert seen["x_scale"].tolist() == [*TYPICAL, *gain_scales, *TYPICAL_EFFECTS]


FCS = [0.6666666666666666, 1.6227646816795556, 3.950047818159824, 9.614997135382728, 23.404316648623773]
FCS += [56.969547684347205, 138.67225487012703, 337.54865629816175, 821.643056683572, 2000.0, 5000.0]
# 16 natural frequencies from 5 cycles per record (3 s) to 0.9 × 0.9 × the Nyquist frequency.
FNS = [1.6666666666666667, 2.4037492838456807, 3.466806371753173, 5.000000000000001, 7.211247851537043]
FNS += [10.400419115259519, 15.000000000000004, 21.63374355461113, 31.201257345778565, 45.00000000000001]
FNS += [64.90123066383339, 93.60377203733569, 135.00000000000014, 194.70369199150022, 280.81131611200703, 405.0]
STARTS = {
    "creep": [
        {
            "tau_s": [
                0.01,
                0.03129134644531899,
                0.09791483623609769,
                0.30638870628004045,
                0.9587315155141828,
                3.0,
            ],
            "gain_um_per_v": [0.0] * 6,
        }
    ],
    "input_lag": [{"fc_hz": f} for f in FCS],
    "resonance": [*({"fn_hz": f, "zeta": z} for f in FNS for z in (0.03, 0.15, 0.5)), {"fn_hz": 441.0, "zeta": 0.7}],
    "drift": [{"rate_um_per_s": 0.0}],
    "delay": [{"samples": k} for k in (1, 2, 3, 4)],
}


def _same_starts(got, want):
    """The start lists agree in length, keys and integers, and in every float to 1e-14
    relative: the grids come from NumPy (``geomspace``), whose last bit may differ
    between releases."""
    if isinstance(want, dict):
        return isinstance(got, dict) and got.keys() == want.keys() and all(_same_starts(got[k], want[k]) for k in want)
    if isinstance(want, list):
        return isinstance(got, list) and len(got) == len(want) and all(map(_same_starts, got, want))
    if isinstance(want, float):
        return isinstance(got, float) and math.isclose(got, want, rel_tol=1e-14, abs_tol=0.0)
    return type(got) is type(want) and got == want


def test_start_lists_are_compared_to_rounding_only():
    assert _same_starts(STARTS["resonance"], [dict(s) for s in STARTS["resonance"]])
    nudged = [dict(s, fn_hz=s["fn_hz"] * (1 + 2e-16)) for s in STARTS["resonance"]]
    assert _same_starts(nudged, STARTS["resonance"])
    moved = [dict(s, fn_hz=s["fn_hz"] * (1 + 1e-9)) for s in STARTS["resonance"]]
    assert not _same_starts(moved, STARTS["resonance"])
    assert not _same_starts(STARTS["resonance"][:-1], STARTS["resonance"])
    assert not _same_starts([{"samples": 1.0}], [{"samples": 1}])


@pytest.mark.parametrize("name", list(STARTS))
def test_candidate_starts_are_unchanged(name):
    others = EffectSet(**{k: v for k, v in PINNED.items() if k != name})
    starts = candidate_starts(name, _record(), P, others, 0.0, max_delay=4)
    assert _same_starts([s.to_dict()[name] for s in starts], _with_peak(name, STARTS[name], others))
    assert all(s.to_dict() == {**others.to_dict(), name: s.to_dict()[name]} for s in starts)


def _with_peak(name, grid, others):
    """The grid of starts of ``name``, with a resonance's starts at the peaks of the
    current residual on :func:`_record`."""
    if name not in ("resonance", "resonance2"):
        return grid
    peaks = residual_peaks_hz(Start(_record(), P, others, 0.0))
    assert peaks
    return [*grid, *({"fn_hz": peak, "zeta": z} for peak in peaks for z in PEAK_ZETAS)]


def test_a_resonance_is_started_at_the_peak_of_the_residual_spectrum():
    # A mode at 300 Hz (ζ = 0.02) rings after a step in the middle of the record: the
    # grid's nearest natural frequencies are 281 and 405 Hz; the peak of the residual's
    # spectrum is within the Welch resolution (4 Hz) of the mode.
    t = np.arange(3001) * DT
    u = np.where(t < 1.5, 20.0, 60.0)
    x, _ = simulate(P, u, DT)
    after = np.clip(t - 1.5, 0.0, None)
    x = x + np.where(t >= 1.5, 0.2 * np.exp(-2 * np.pi * 300.0 * 0.02 * after) * np.sin(2 * np.pi * 300.0 * after), 0.0)
    rec = validate_record(u, x, DT)
    peak = residual_peaks_hz(Start(rec, P, EffectSet(), 0.0))[0]
    assert abs(peak - 300.0) <= 4.0
    starts = [s.to_dict()["resonance"] for s in candidate_starts("resonance", rec, P, EffectSet(), 0.0)]
    assert {"fn_hz": peak, "zeta": PEAK_ZETAS[0]} in starts


def test_a_mode_that_rings_only_after_a_sharp_start_is_started_at_its_burst():
    # A decaying sine starts at full slope and a mode at 829 Hz (ζ = 0.065) rings for a
    # few milliseconds of a 1.2 s record at 10 kHz, under 20 nm of noise: averaged over
    # the record its line sinks below the noise (the whole-record peak is elsewhere),
    # over the 20 ms stretch where the residual's energy is largest it stands out.
    dt, fn, zeta = 1e-4, 829.0, 0.065
    t = np.arange(12000) * dt
    u = 50.0 + 48.0 * np.exp(-t / 0.5) * np.sin(2 * np.pi * 20.0 * t)
    x, _ = simulate(P, u, dt)
    wd = 2 * np.pi * fn * math.sqrt(1 - zeta**2)
    ring = 0.25 * np.exp(-2 * np.pi * fn * zeta * t) * np.sin(wd * t)
    x = x + ring + np.random.default_rng(124).normal(0.0, 0.02, t.size)
    peaks = residual_peaks_hz(Start(validate_record(u, x, dt), P, EffectSet(), 0.0))
    assert len(peaks) == 2
    assert abs(peaks[0] - fn) > 100.0
    assert abs(peaks[1] - wd / (2 * np.pi)) <= 25.0


TYPED = (
    Creep(tau_s=(0.01, 0.5), gain_um_per_v=(0.003, 0.004)),
    InputLag(fc_hz=80.0),
    GainDrift(rate_per_s=0.01),
    Electrostriction(epsilon_per_um=0.004),
    Resonance(fn_hz=150.0, zeta=0.1),
    Resonance2(fn_hz=300.0, zeta=0.2),
    Drift(rate_um_per_s=0.2),
    Delay(samples=2),
    Pickup(line_hz=50.0, sin_um=(0.1, 0.0), cos_um=(0.02, 0.01)),
    Saturation(min_um=-1.0, max_um=30.0),
    BetweenSamples(input="hold"),
)
#: The typed effects of PINNED.
TYPED_PINNED = tuple(e for e in TYPED if e.name in PINNED)


def test_the_registry_is_the_core_vocabulary_in_chain_order():
    assert tuple(EffectSet.vocabulary) == VOCABULARY
    assert tuple(type(e) for e in TYPED) == EFFECTS
    assert all(getattr(boucwen, cls.__name__) is cls for cls in EFFECTS)


def test_typed_effects_round_trip_through_effect_set_dict_and_json():
    s = effect_set(*reversed(TYPED))
    assert s == EffectSet(**ALL)
    assert effects_of(s) == TYPED
    text = to_json(s)
    assert json.loads(text) == ALL
    assert from_json(text) == s
    assert effects_of(from_json(to_json(effect_set(*TYPED)))) == TYPED
    assert effects_of(EffectSet()) == () and from_json(to_json(EffectSet())) == EffectSet()
    for e in TYPED:
        assert type(e).from_dict(e.to_dict()) == e
        assert e.to_dict() == ALL[e.name]


def test_typed_effects_are_frozen_hashable_picklable_and_print_as_code():
    for e in TYPED:
        assert pickle.loads(pickle.dumps(e)) == e
        assert eval(repr(e), {type(e).__name__: type(e)}) == e
    assert len(set(TYPED + TYPED)) == len(TYPED)
    with pytest.raises(dataclasses.FrozenInstanceError):
        TYPED[1].fc_hz = 1.0  # type: ignore[misc]


def test_parameters_are_stored_as_the_core_holds_them():
    c = Creep(tau_s=np.array([0.1, 1.0]), gain_um_per_v=[1, 2])
    assert c.tau_s == (0.1, 1.0) and c.gain_um_per_v == (1.0, 2.0)
    assert all(type(v) is float for v in c.tau_s + c.gain_um_per_v)
    assert type(InputLag(650).fc_hz) is float and InputLag(650) == InputLag(650.0)
    assert type(Delay(np.int64(3)).samples) is int


@pytest.mark.parametrize(
    "build, exc, words",
    [
        (lambda: InputLag(0.0), ValueError, "input_lag.fc_hz"),
        (lambda: InputLag(math.nan), ValueError, "input_lag.fc_hz"),
        (lambda: InputLag("fast"), TypeError, "input_lag.fc_hz must be a number"),
        (lambda: InputLag(True), TypeError, "input_lag.fc_hz must be a number"),
        (lambda: Resonance(fn_hz=100.0, zeta=-0.1), ValueError, "resonance.zeta"),
        (lambda: Resonance(fn_hz=-5.0, zeta=0.1), ValueError, "resonance.fn_hz"),
        (lambda: Drift(math.inf), ValueError, "drift.rate_um_per_s"),
        (lambda: Delay(-1), ValueError, "delay.samples"),
        (lambda: Delay(1.5), TypeError, "delay.samples must be an integer"),
        (lambda: Creep(tau_s=(1.0, 2.0), gain_um_per_v=(0.1,)), ValueError, "creep.gain_um_per_v"),
        (lambda: Creep(tau_s=(0.0,), gain_um_per_v=(0.1,)), ValueError, "creep.tau_s"),
        (lambda: GainDrift(math.nan), ValueError, "gain_drift.rate_per_s"),
        (lambda: Electrostriction(math.inf), ValueError, "electrostriction.epsilon_per_um"),
        (lambda: Resonance2(fn_hz=100.0, zeta=0.0), ValueError, "resonance2.zeta"),
        (lambda: Resonance2(fn_hz=0.0, zeta=0.1), ValueError, "resonance2.fn_hz"),
        (lambda: Pickup(line_hz=-50.0, sin_um=(0.0,), cos_um=(0.0,)), ValueError, "pickup.line_hz"),
        (lambda: Pickup(line_hz=50.0, sin_um=(), cos_um=()), ValueError, "pickup.sin_um"),
        (lambda: Pickup(line_hz=50.0, sin_um=(0.1,), cos_um=(0.1, 0.2)), ValueError, "pickup.cos_um"),
        (lambda: Pickup(line_hz=50.0, sin_um=(math.nan,), cos_um=(0.0,)), ValueError, "pickup.sin_um"),
        (lambda: Saturation(min_um=math.nan, max_um=1.0), ValueError, "saturation.min_um"),
        (lambda: Saturation(min_um=2.0, max_um=1.0), ValueError, "saturation.max_um"),
        (lambda: Saturation.from_dict({"min_um": 0.0}), ValueError, "saturation: missing parameter 'max_um'"),
        (lambda: InputLag.from_dict({"fc": 1.0}), ValueError, "input_lag: unknown parameter 'fc'"),
        (lambda: Resonance.from_dict({"fn_hz": 1.0}), ValueError, "resonance: missing parameter 'zeta'"),
        (lambda: Drift.from_dict(0.1), TypeError, "drift must be a dict"),
        (lambda: effect_set(InputLag(1.0), InputLag(2.0)), ValueError, "'input_lag' given more than once"),
        (lambda: effect_set({"fc_hz": 1.0}), TypeError, "effect_set takes effects"),
    ],
)
def test_invalid_typed_effects_name_the_culprit(build, exc, words):
    with pytest.raises(exc, match=words.replace(".", r"\.")):
        build()


@pytest.mark.parametrize(
    "text, words",
    [
        ('{"hum": {}}', "unknown effect 'hum'"),
        ('{"drift": {"rate": 1.0}}', "drift: unknown parameter 'rate'"),
        ('{"resonance": {"fn_hz": 100.0}}', "resonance: missing parameter 'zeta'"),
        ('{"drift": {"rate_um_per_s": "fast"}}', "drift.rate_um_per_s must be a number"),
        ('{"input_lag": {"fc_hz": -1.0}}', "input_lag.fc_hz"),
        ('{"delay": {"samples": 1.5}}', "delay.samples must be an integer"),
        ('{"drift": 3}', "drift must be a dict"),
        ("[1, 2]", "expected a JSON object"),
        ("{", "not valid JSON"),
    ],
)
def test_bad_json_is_a_value_error_naming_the_culprit(text, words):
    with pytest.raises(ValueError, match=words.replace(".", r"\.")):
        from_json(text)


def test_layout_of_typed_effects_is_the_layout_of_their_set():
    typed = Layout(effects=TYPED_PINNED, dt=DT, duration_s=3.0)
    of_set = Layout.of(EffectSet(**PINNED), DT, 3.0)
    assert typed == of_set and typed.names == tuple(PINNED)
    whole = Layout(effects=TYPED, dt=DT, duration_s=3.0)
    assert whole == Layout.of(EffectSet(**ALL), DT, 3.0) and whole.names == VOCABULARY
    assert whole.labels() == [
        *LABELS[:11],
        *["gain_drift.rate", "electrostriction.epsilon", *LABELS[11:13], "resonance2.ln_fn", "resonance2.ln_zeta"],
        *[LABELS[13], "pickup.sin[1]", "pickup.sin[2]", "pickup.cos[1]", "pickup.cos[2]"],
        *["saturation.min", "saturation.max"],
    ]
    assert typed.labels() == LABELS
    v = typed.pack(P, effect_set(*TYPED_PINNED), 0.1)
    assert v.tolist() == V0
    p, e, h0 = typed.unpack(v)
    assert p == P and h0 == 0.1
    np.testing.assert_allclose(typed.pack(p, e, h0), v, rtol=1e-15)
    creep, *_, delay = effects_of(e)
    assert creep == TYPED[0] and delay == TYPED_PINNED[-1]  # fitted exactly, and fixed
    with pytest.raises(ValueError, match="layout is for the effects"):
        typed.pack(P, EffectSet(), 0.1)


def test_every_effect_declares_one_of_each_per_unknown():
    ctx = Context(dt=DT, duration_s=3.0)
    for e in TYPED:
        n = len(e.unknowns())
        assert len(e.pack()) == n and len(e.bounds(ctx)) == n
        assert len(e.sign_bounds(1.0)) == n and len(e.typical(ctx, 100.0, 15.0)) == n
        assert type(e.unpack(e.pack())) is type(e)


def test_starts_of_the_new_effects():
    rec = _record()
    n = len(rec)
    others = EffectSet(**PINNED)

    def starts(name):
        return [s.to_dict()[name] for s in candidate_starts(name, rec, P, others, 0.0, max_delay=4)]

    assert starts("gain_drift") == [{"rate_per_s": 0.0}]
    # ε·span² = b·span for each bend b: the square bends the stroke by that share of the span.
    span = float(np.ptp(rec.x))
    assert starts("electrostriction") == [{"epsilon_per_um": b / span} for b in STROKE_BENDS]
    assert _same_starts(starts("resonance2"), _with_peak("resonance2", STARTS["resonance"], others))
    # The extremes, and each end at the reading's 1 % quantile with the other at its extreme.
    lo, hi = float(rec.x.min()), float(rec.x.max())
    q_lo, q_hi = (float(v) for v in np.quantile(rec.x, [0.01, 0.99]))
    assert starts("saturation") == [
        {"min_um": lo, "max_um": hi},
        {"min_um": lo, "max_um": q_hi},
        {"min_um": q_lo, "max_um": hi},
    ]
    # 50 and 60 Hz, three harmonics each below the 500 Hz Nyquist frequency, the
    # amplitudes fitted to the residual of the current model.
    lines = starts("pickup")
    assert [(p["line_hz"], len(p["sin_um"]), len(p["cos_um"])) for p in lines] == [(50.0, 3, 3), (60.0, 3, 3)]
    coarse = validate_record(rec.u[::8], rec.x[::8], 8 * DT)  # Nyquist 62.5 Hz: one harmonic each
    got = [s.to_dict()["pickup"] for s in candidate_starts("pickup", coarse, P, EffectSet(), 0.0)]
    assert [(p["line_hz"], len(p["sin_um"])) for p in got] == [(50.0, 1), (60.0, 1)]
    assert n == 3001


def test_the_measurement_chain_is_given_to_a_fit_not_proposed_by_the_search():
    from boucwen.diagnosis.search import proposals

    added = {m.adds[-1] for m in proposals((), {}, 3) if m.kind in ("add", "add_tied")}
    assert "between_samples" not in added
    assert added == {cls.name for cls in EFFECTS if cls.proposed}
    assert [cls.name for cls in EFFECTS if not cls.proposed] == ["between_samples"]
