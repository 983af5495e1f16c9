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


def test_checks_hold_on_both_halves(rows):
    by_half = figures_by_half(rows)
    results = checks(by_half)
    assert len(results) == len(TARGETS)
    failed = [line for line, ok in results if not ok]
    assert not failed, (failed, confusion_table(rows))


def test_the_halves_are_reported_side_by_side(rows):
    table = confusion_table(rows)
    assert all(h in table.splitlines()[0] for h in HALVES)
    by_half = figures_by_half(rows)
    assert sum(by_half[h]["records"] for h in HALVES) == len(rows)
