"""Decisions with margins (boucwen.diagnosis.margins): close choices are made by the
stated rule, noted, and the diagnosis gives the same answer when only the last bits of
the arithmetic change."""

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from boucwen import diagnose
from boucwen.diagnosis.margins import ANSWER, PATH, CloseCalls, at_least, decide, first_of_best
from boucwen.experiments.suite_records import make_suite_record


def test_a_comparison_within_the_margin_takes_the_simpler_side_and_is_noted():
    calls = CloseCalls()
    assert at_least(0.1 + 1e-6, 0.1, 1e-4, "creep: earns", calls) is False
    assert at_least(0.1 - 1e-6, 0.1, 1e-4, "drift: earns", calls) is False
    assert at_least(0.1 + 1e-3, 0.1, 1e-4, "delay: earns", calls) is True
    assert at_least(0.1 - 1e-3, 0.1, 1e-4, "pickup: earns", calls) is False
    assert [c["decision"] for c in calls.to_list()] == ["creep: earns", "drift: earns"]
    assert all(c["kind"] == ANSWER and c["chose"] == "no" for c in calls.to_list())


def test_a_rule_is_close_only_where_a_close_comparison_decides_it():
    calls = CloseCalls()
    # The second comparison is close, but the first passes clearly: not a close call.
    assert decide(lambda c: c.ge(0.5, 0.1) or c.ge(0.3, 0.3), "a", calls) is True
    # Both parts hang on the close comparison: the simpler side, noted.
    assert decide(lambda c: c.ge(0.05, 0.1) or c.ge(0.3, 0.3), "b", calls, kind=PATH) is False
    assert [(c["decision"], c["kind"]) for c in calls.to_list()] == [("b", PATH)]


def test_ties_go_to_the_first_listed_and_clear_winners_win():
    calls = CloseCalls()
    scores = [0.30, 0.50, 0.50 + 1e-9, 0.2]
    assert first_of_best(scores, float, higher=True, margin=1e-4, relative=False, decision="t", calls=calls) == 1
    assert len(calls) == 1
    lowest = first_of_best([3.0, 1.0, 2.0], float, higher=False, margin=1e-4, relative=True, decision="u", calls=calls)
    assert lowest == 1
    assert len(calls) == 1


# Short records of the quick suite (one of nothing, two with an effect), each diagnosed
# in a few seconds.
RECORDS = [
    ((), "multisine", 0, 5_000.0, "paper_1hz", 0.001),
    ((("input_lag", 0.08),), "staircase", 3, 5_000.0, "paper_1hz", 0.005),
    ((("gain_drift", 0.08),), "single_step", 4, 10_000.0, "paper_100hz", 0.005),
]


@pytest.mark.parametrize(("effects", "family", "seed", "fs_hz", "param_set", "noise_um"), RECORDS)
def test_the_last_bits_and_the_blas_threads_do_not_change_the_answer(effects, family, seed, fs_hz, param_set, noise_um):
    # The record as given and scaled by 1 + 1e-12 (its last bits), each diagnosed with
    # one and with two BLAS threads: the same effects with the same confidence.
    rec = make_suite_record(effects, family, seed, fs_hz=fs_hz, param_set=param_set, noise_um=noise_um)
    answers = set()
    for threads in (1, 2):
        for x in (rec.x, rec.x * (1.0 + 1e-12)):
            with threadpool_limits(limits=threads, user_api="blas"):
                d = diagnose(rec.u, x, rec.dt, seed=seed)
            answers.add((tuple(d.effects), tuple(sorted((k, v["level"]) for k, v in d.confidence.items()))))
    assert not np.array_equal(rec.x * (1.0 + 1e-12), rec.x)
    assert len(answers) == 1, answers
    ((named, _),) = answers
    assert list(named) == [name for name, _ in effects]
