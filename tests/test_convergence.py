"""Decisions read converged fits: the diagnosis's answer (the effects named and their
confidence) is the same with the solver's stopping tolerances ten times tighter and
with SciPy's trust-region reflective solver in place of Levenberg–Marquardt, on the
measured benchmark's cases and on six records of the generated suite, three from each
half (the quick subset's first of each half, in its order: three diagnoses a record,
so CI's slow command stays within its time); and every model it returns
there passes the boundedness check (boucwen.boundedness)."""

import pytest

from boucwen import datasets, diagnose
from boucwen.diagnosis import Convergence
from boucwen.experiments.diagnosis_suite import cases, half_of
from boucwen.experiments.measured import CROSS_RECORD, FIT_SHARE, forward_split
from boucwen.experiments.suite_records import make_suite_record

SOLVERS = {"lm": Convergence(), "lm, tolerances ÷10": Convergence().tighter(), "trf": Convergence(method="trf")}


def _answer(u, x, dt, conv, seed=0):
    d = diagnose(u, x, dt, convergence=conv, seed=seed)
    # Whatever the solver, the returned model stays bounded over the record's range.
    assert d.boundedness is not None and d.boundedness.passed, d.boundedness
    return sorted((e.name, e.level) for e in d.named_effects)


def _suite_cases():
    by_half = {}
    for case in cases(quick=True):
        by_half.setdefault(half_of(case.seed), []).append(case)
    return [c for half in sorted(by_half) for c in by_half[half][:3]]


@pytest.mark.slow
@pytest.mark.parametrize("case", _suite_cases(), ids=lambda c: f"seed{c.seed}")
def test_the_answer_on_suite_records_does_not_depend_on_the_solver(case):
    rec = make_suite_record(
        case.effects, case.family, case.seed, fs_hz=case.fs_hz, param_set=case.param_set, noise_um=case.noise_um
    )
    answers = {name: _answer(rec.u, rec.x, rec.dt, conv, case.seed) for name, conv in SOLVERS.items()}
    assert len(set(map(tuple, answers.values()))) == 1, (rec.label, answers)


def _measured_records():
    """The records the measured benchmark's cases diagnose: the identification record
    (its cross-record case) and the first 60 % of each record (its forward splits)."""
    out = []
    for name in ("micromanipulator", "micromanipulator_compensated"):
        try:
            rec = datasets.load(name)
        except datasets.DataNotFoundError:
            continue
        if name == CROSS_RECORD[0]:
            out.append(pytest.param(rec, id=name))
        out.append(pytest.param(forward_split(rec, FIT_SHARE).fitted, id=f"{name}-first-60"))
    return out or [pytest.param(None, id="no-measured-data")]


@pytest.mark.slow
@pytest.mark.parametrize("rec", _measured_records())
def test_the_answer_on_measured_records_does_not_depend_on_the_solver(rec):
    if rec is None:
        pytest.skip("no measured record here ($BOUCWEN_DATA or ../shared/data)")
    answers = {name: _answer(rec.u, rec.x, rec.dt, conv) for name, conv in SOLVERS.items()}
    assert len(set(map(tuple, answers.values()))) == 1, (rec.name, answers)
