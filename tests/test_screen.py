"""The judge's screen decides nothing the converged refits would decide otherwise: the
diagnosis with its held-out errors screened (the default) and with every one from
converged refits (``Convergence(screen=False)``) take the same decisions, on records of
the evaluation suite's development half and on the shared measured records."""

import pytest

from boucwen import datasets
from boucwen.diagnosis import Convergence, diagnose_record
from boucwen.experiments import diagnosis_suite as ds
from boucwen.experiments.suite_records import make_suite_record
from boucwen.record import validate_record

pytestmark = pytest.mark.slow


def _verdicts(d):
    return [(x.label, x.accepted) for x in d.decisions], list(d.effects)


def _both(record, seed):
    screened = diagnose_record(record, seed=seed, workers=1)
    exact = diagnose_record(record, seed=seed, workers=1, convergence=Convergence(screen=False))
    return screened, exact


@pytest.mark.parametrize("seed", [c.seed for c in ds.cases(quick=True) if ds.half_of(c.seed) == "development"][:6])
def test_the_screen_takes_the_decisions_the_refits_take_on_the_development_half(seed):
    c = next(c for c in ds.cases(quick=True) if c.seed == seed)
    rec = make_suite_record(c.effects, c.family, c.seed, fs_hz=c.fs_hz, param_set=c.param_set, noise_um=c.noise_um)
    screened, exact = _both(validate_record(rec.u, rec.x, rec.dt), seed)
    assert _verdicts(screened) == _verdicts(exact)
    # Every decision the screened run took read refits, and so did every accepted move
    # that could have changed what a round took: an accepted drop, any member of the
    # taken move's ambiguity set. An accepted add the taken move beats clearly may stay
    # screened (its verdict is the refits' all the same: above).
    taken = [d for d in screened.taken]
    assert all(d.exact for d in taken)
    tied = {a["move"] for r in screened.evidence["rounds"] for a in r["ambiguity"]}
    for d in screened.decisions:
        if d.accepted and not d.exact:
            assert d.move != "drop" and d.label not in tied, d.label


@pytest.mark.parametrize("name", ["micromanipulator", "micromanipulator_compensated"])
def test_the_screen_takes_the_decisions_the_refits_take_on_the_measured_records(name):
    try:
        rec = datasets.load(name)
    except datasets.DataNotFoundError as exc:
        pytest.skip(str(exc))
    screened, exact = _both(rec, 0)
    assert _verdicts(screened) == _verdicts(exact)
