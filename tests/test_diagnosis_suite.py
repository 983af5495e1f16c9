"""The quick subset of the diagnosis evaluation suite, held to the suite's checks.

``python -m boucwen.experiments.diagnosis_suite`` runs the full suite (docs). Here the
quick subset (one record per effect of the vocabulary, two pairs, two clean records,
three effects outside the vocabulary) is generated and diagnosed once, both halves, and
each check of ``TARGETS`` is asserted on it; the named-right share is reported, not
targeted.
"""

import io

import pytest

from boucwen.experiments.diagnosis_suite import (
    HALVES,
    TARGETS,
    cases,
    checks,
    confusion_table,
    figures_by_half,
    half_of,
    run_suite,
)


@pytest.fixture(scope="module")
def rows():
    log = io.StringIO()
    out = run_suite(quick=True, err=log)
    assert len(log.getvalue().splitlines()) >= len(out)  # one progress line per record
    return out


def test_quick_subset_covers_every_kind_and_both_halves():
    quick = cases(quick=True)
    kinds = {len(c.effects) for c in quick}
    assert {0, 1, 2} <= kinds
    assert len({c.family for c in quick}) >= 6
    assert len(cases()) >= 150
    assert {half_of(c.seed) for c in quick} == set(HALVES)
    assert {half_of(c.seed) for c in cases()} == set(HALVES)


#: The check the held-out half does not meet (a strict xfail below, so that it shows
#: when it holds), and why.
NOT_MET = "confident_right [held_out]"
NOT_MET_REASON = (
    "two confident names wrong of nine on the held-out half: a sensor clip on a 20 kHz staircase named "
    "electrostriction (the clip holds one step's hold alone, which an offset of that hold, and the curvature "
    "that lowers the top step, explain as well), and a drift beside a 0.3 µm creep on the stack record "
    "(rest, step, slow sine); the full suite's development records of those kinds (seeds 238, 252, 308) are "
    "named right, but a generated 20 kHz clipped staircase outside the suite gets the electrostriction beside "
    "the clip, both confident (the clip alone leaves 21 nm held-out at 1 nm of noise there; why is not "
    "established)"
)


def _check_lines(rows):
    results = checks(figures_by_half(rows))
    assert len(results) == len(TARGETS)
    return results


def test_checks_hold_on_both_halves(rows):
    failed = [line for line, ok in _check_lines(rows) if not ok and not line.startswith(NOT_MET)]
    assert not failed, (failed, confusion_table(rows))


@pytest.mark.xfail(strict=True, reason=NOT_MET_REASON)
def test_confident_names_are_right_on_the_held_out_half(rows):
    lines = [(line, ok) for line, ok in _check_lines(rows) if line.startswith(NOT_MET)]
    assert len(lines) == 1
    assert lines[0][1], (lines[0][0], confusion_table(rows))


def test_the_halves_are_reported_side_by_side(rows):
    table = confusion_table(rows)
    assert all(h in table.splitlines()[0] for h in HALVES)
    by_half = figures_by_half(rows)
    assert sum(by_half[h]["records"] for h in HALVES) == len(rows)
