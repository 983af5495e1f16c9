"""The backward step of the diagnosis (boucwen.diagnosis.backward) on a small constructed
record: a drift of 2 µm/s under a sine with square steps (1 kHz, 2 s, 5 nm of noise)."""

import pytest

from boucwen import DiagnosisPolicy, EffectSet, Params
from boucwen.diagnosis.backward import backward_step
from boucwen.diagnosis.credit import Credit, earns
from boucwen.effects import candidate_starts, fit_extended_record
from boucwen.record import validate_record

POLICY = DiagnosisPolicy()
P = Params.paper_1hz()


@pytest.fixture(scope="module")
def record(drift_record):
    return drift_record


def _creep_start(record):
    return candidate_starts("creep", record, P, EffectSet(), 0.0)[0]


def _noop(_message):
    pass


def test_an_effect_kept_first_whose_work_a_later_one_does_is_dropped(record):
    # Creep kept beside the drift that explains the record: taken out, the drift refitted
    # alone does as well, and creep goes; the drift earns its place.
    start = EffectSet.from_dict({**_creep_start(record).to_dict(), "drift": {"rate_um_per_s": 1.0}})
    current = fit_extended_record(record, P, start, 0.0, max_nfev=30)
    evidence = {}
    _, left = backward_step(
        record, record, current, ["creep", "drift"], evidence, null=None, policy=POLICY, workers=1, say=_noop
    )
    assert left == ["drift"]
    pruned = evidence["pruned"]
    assert not earns(Credit.from_dict(pruned["creep"]), POLICY)
    assert earns(Credit.from_dict(pruned["drift"]), POLICY)


def test_on_a_short_record_every_look_alike_is_tried_in_the_backward_step(record):
    # Creep alone, imitating the drift, earns its place against the base model; the
    # look-alike test on the base model's residual names creep, yet on a record not
    # screened every member of the group is tried in its place, and the drift, earning
    # more, is swapped in.
    current = fit_extended_record(record, P, _creep_start(record), 0.0, max_nfev=30)
    evidence = {}
    _, left = backward_step(
        record, record, current, ["creep"], evidence, null=None, policy=POLICY, workers=1, say=_noop
    )
    assert left == ["drift"]
    creep = evidence["pruned"]["creep"]
    swap = creep["swapped_for"]["drift"]
    assert earns(Credit.from_dict(creep), POLICY)
    assert swap["gain_over_null"] > creep["gain_over_null"] and swap["test_named"] == "creep"


def test_a_look_alike_is_swapped_only_for_the_one_the_test_names_on_a_screened_copy(record):
    # The same model judged on a screened copy (another record of the same samples): only
    # the member the test names is tried, and it names creep itself, so creep stays.
    current = fit_extended_record(record, P, _creep_start(record), 0.0, max_nfev=30)
    copy = validate_record(record.u, record.x, record.dt)
    evidence = {}
    _, left = backward_step(record, copy, current, ["creep"], evidence, null=None, policy=POLICY, workers=1, say=_noop)
    assert left == ["creep"] and "swapped_for" not in evidence["pruned"]["creep"]
