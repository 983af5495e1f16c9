"""The next experiment (boucwen.diagnosis.experiment) and the set settled on the record it
proposes (boucwen.diagnosis.unseen.settled): constructed models and records first, then
the loop closed on a generated plant, from Python and from the shell."""

import math

import numpy as np
import pytest

from boucwen import DiagnosisPolicy, EffectSet, Params, diagnose, simulate_extended
from boucwen.cli import main
from boucwen.diagnosis.experiment import (
    Experiment,
    Explanation,
    Limits,
    _input,
    design,
    separation,
)
from boucwen.diagnosis.unseen import settled
from boucwen.effects import ExtendedFit
from boucwen.experiments.experiment_design import run_case
from boucwen.record import validate_record

DT = 2e-4


def _record(n=5000, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    u = 50 - 30 * np.cos(2 * np.pi * 5 * t)
    x = simulate_extended(Params.paper_1hz(), EffectSet(), u, DT) + rng.normal(0, 0.005, n)
    return validate_record(u, x, DT)


def _member(effects, record, label=None):
    fit = ExtendedFit(Params.paper_1hz(), effects, 0.0, 0.0, 0.0, 0, True)
    x = simulate_extended(fit.params, effects, record.u, record.dt)
    return Explanation(label or ("+".join(effects.names) or "base model"), tuple(effects.names), fit, x, math.nan)


def test_limits_not_given_come_from_the_record_and_bad_ones_are_named():
    rec = _record()
    lim = Limits.of(rec, 2.0, None, None, None, None)
    assert lim.u_min_v == pytest.approx(rec.u.min()) and lim.u_max_v == pytest.approx(rec.u.max())
    assert lim.max_slew_v_per_s == pytest.approx(np.max(np.abs(np.diff(rec.u))) / DT)
    assert lim.dt_s == DT and lim.samples == 10_000
    for kwargs, word in (
        ({"duration_s": 0.0}, "duration_s"),
        ({"duration_s": float("nan")}, "duration_s"),
        ({"u_min": 90.0, "u_max": 10.0}, "u_max must exceed u_min"),
        ({"max_slew_v_per_s": -1.0}, "max_slew_v_per_s"),
        ({"dt": 0.0}, "dt"),
        ({"duration_s": 0.001}, "at least 100 samples"),
        ({"u_min": "low"}, "u_min"),
    ):
        args = {"duration_s": 2.0, "u_min": None, "u_max": None, "max_slew_v_per_s": None, "dt": None, **kwargs}
        with pytest.raises(ValueError, match=word):
            Limits.of(rec, args["duration_s"], args["u_min"], args["u_max"], args["max_slew_v_per_s"], args["dt"])


def test_every_input_of_the_design_keeps_within_the_range_and_the_slew():
    lim = Limits(10.0, 90.0, 2000.0, DT, 1.0)
    rng = np.random.default_rng(4)
    for _ in range(200):
        u, parts = _input(rng.uniform(size=24), lim, 6)
        assert u.size == lim.samples
        assert u.min() >= lim.u_min_v - 1e-9 and u.max() <= lim.u_max_v + 1e-9
        assert np.max(np.abs(np.diff(u))) / DT <= lim.max_slew_v_per_s * (1 + 1e-9)
        assert {p.kind for p in parts} <= {"step", "burst", "hold"}


def test_the_separation_ignores_what_a_new_record_reestimates():
    t = np.linspace(0, 1, 1000)
    x = np.sin(2 * np.pi * 3 * t)
    assert separation(x, x + 0.3 + 2.0 * t, 0.01) < 1e-9
    assert separation(x, x + 0.01 * np.sin(2 * np.pi * 20 * t), 0.01) == pytest.approx(math.sqrt(0.5), rel=0.02)


def test_the_designed_input_separates_two_lookalikes_at_least_as_well_as_the_generic_one():
    rec = _record()
    members = (
        _member(EffectSet(input_lag={"fc_hz": 60.0}), rec),
        _member(EffectSet(delay={"samples": 13}), rec),
    )
    lim = Limits.of(rec, 1.0, None, None, None, None)
    exp = design(rec, members, 0.005, lim, seed=1)
    assert isinstance(exp, Experiment) and exp.ambiguous
    assert exp.u.size == lim.samples and exp.dt == DT
    assert exp.min_separation >= exp.generic_min_separation > 0
    (sep,) = exp.separations
    assert {sep.a, sep.b} == {"input_lag", "delay"}
    assert exp.features and all(0.1 <= f.share <= 1 for f in exp.features)
    assert len(exp.segments) == 3 and all(set(s.errors_um) == {"input_lag", "delay"} for s in exp.segments)
    assert exp.to_dict()["separations"][0]["designed"] == pytest.approx(sep.designed)


def test_without_rivals_it_says_no_experiment_is_needed(tmp_path):
    rec = _record()
    exp = design(rec, (_member(EffectSet(), rec),), 0.005, Limits.of(rec, 1.0, None, None, None, None))
    assert not exp.ambiguous and exp.u.size == 0
    assert "no experiment is needed" in exp.summary()
    with pytest.raises(ValueError, match="no experiment to write"):
        exp.write_csv(tmp_path / "e.csv")


def test_a_second_record_refutes_the_explanation_it_contradicts():
    rec = _record()
    truth = EffectSet(input_lag={"fc_hz": 60.0})
    lag, delay = _member(truth, rec), _member(EffectSet(delay={"samples": 13}), rec)
    lim = Limits.of(rec, 1.0, None, None, None, None)
    exp = design(rec, (lag, delay), 0.005, lim, seed=1)
    x_b = simulate_extended(Params.paper_1hz(), truth, exp.u, DT) + np.random.default_rng(9).normal(
        0, 0.005, exp.u.size
    )
    said: list[str] = []
    left, decisions = settled(
        [validate_record(exp.u, x_b, DT)],
        [lag.fit, delay.fit],
        ["input_lag", "delay"],
        DiagnosisPolicy(),
        0.005,
        said.append,
    )
    assert left == (0,)
    assert [d.accepted for d in decisions if d.candidate == ("input_lag",)] == [True]
    assert any("refuted" in line and "delay" in line for line in said)
    # Two explanations the record cannot tell apart both stay.
    left, _ = settled(
        [validate_record(exp.u, x_b, DT)], [lag.fit, lag.fit], ["a", "b"], DiagnosisPolicy(), 0.005, said.append
    )
    assert left == (0, 1)


def test_a_diagnosis_read_back_holds_no_record_to_design_with():
    d = diagnose(_record().u, _record().x, DT, max_effects=0)
    with pytest.raises(ValueError, match="duration_s"):
        d.next_experiment(duration_s=-1.0)
    from dataclasses import replace

    with pytest.raises(ValueError, match="holds no record"):
        replace(d, explained=None).next_experiment()


@pytest.mark.slow  # two diagnoses and a designed experiment on generated plants
@pytest.mark.parametrize("effect, seed", [("delay", 0)])
def test_the_loop_closes_on_a_generated_plant(effect, seed):
    # A delay under one slow sine looks like an input lag or a creep; the record of the
    # designed input settles it (boucwen.experiments.experiment_design, one case).
    row = run_case(effect, seed)
    assert row["tied"], row["first_named"]
    assert row["designed"] > row["generic"]
    assert row["right"] and not row["wrong_confident"], row["settled_named"]


def test_the_shell_writes_the_experiment_and_takes_its_record_back(tmp_path, capsys):
    rng = np.random.default_rng(0)
    n = 6000
    t = np.arange(n) * DT
    p = Params.paper_1hz()
    truth = EffectSet(delay={"samples": 12})
    u = 50 - 30 * np.cos(2 * np.pi * 5 * t)
    x = simulate_extended(p, truth, u, DT) + rng.normal(0, 0.005, n)
    a = tmp_path / "a.csv"
    np.savetxt(a, np.column_stack([t, u, x]), delimiter=",", header="t,u,x", comments="")
    e, fig = tmp_path / "e.csv", tmp_path / "e.png"
    code = main(["diagnose", str(a), "--next-experiment", str(e), "--duration", "1.2", "--experiment-plot", str(fig)])
    out = capsys.readouterr().out
    assert code == 0
    assert "next experiment:" in out
    if "no experiment is needed" in out:
        assert not e.exists()
        return
    assert fig.stat().st_size > 0
    data = np.genfromtxt(e, delimiter=",", names=True)
    assert data.dtype.names == ("t_s", "u_V") and data.size == 6000
    x_b = simulate_extended(p, truth, data["u_V"], DT) + rng.normal(0, 0.005, data.size)
    b = tmp_path / "b.csv"
    np.savetxt(b, np.column_stack([data["t_s"], data["u_V"], x_b]), delimiter=",", header="t,u,x", comments="")
    assert main(["diagnose", str(a), "--validate", str(b)]) == 0
    out = capsys.readouterr().out
    assert "delay: confident" in out, out


def test_bad_limits_in_the_shell_fail_before_the_work_with_one_line(tmp_path, capsys):
    a = tmp_path / "a.csv"
    rec = _record(2000)
    np.savetxt(a, np.column_stack([rec.t, rec.u, rec.x]), delimiter=",", header="t,u,x", comments="")
    code = main(["diagnose", str(a), "--next-experiment", str(tmp_path / "e.csv"), "--duration", "0"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert "duration_s" in err
    assert not (tmp_path / "e.csv").exists()
