"""The judge calibrated on records of the suite's development half
(boucwen.experiments.judge_calibration): on clean records and on records whose effect is
already in the model, no move can improve, and the test of one move at the nominal
level accepts at most that share of them; and the screen's verdict never differs from the
refits' outside its band. The figures are printed (``pytest -s`` shows them)."""

import json

import pytest

from boucwen.diagnosis import DiagnosisPolicy
from boucwen.experiments.judge_calibration import NOMINAL_ALPHA, calibration_cases, judge_moves, summary

pytestmark = pytest.mark.slow


def test_the_false_accept_rate_per_move_is_at_most_the_nominal_level_and_the_band_misses_nothing():
    policy = DiagnosisPolicy()
    rows = []
    # 16 records: a reference proposes 2-5 add moves (the vocabulary's moves its record
    # can hold), and the rate per move needs at least 40 of them to be read against 5 %.
    for case in calibration_cases(16):
        rows += judge_moves(case, policy, workers=None)
    result = summary(rows, policy.screen_band)
    print("\n" + json.dumps(result, indent=1))
    assert result["moves"] >= 40
    assert result["false_accept_rate_nominal"] <= NOMINAL_ALPHA
    assert result["decisions_the_band_misses"] == 0
