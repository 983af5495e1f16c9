"""Feeding an identifier as a loop would (boucwen.pacing): real time, one sample per dt."""

import time

import numpy as np
import pytest

from boucwen import Identifier
from boucwen.pacing import COOPERATIVE_INTERVALS, REFINE_MODES, PacedFeed, feed_for, refine_modes
from conftest import split_record, split_start

DT = 1e-4


#: A short record (2 000 samples) and starting values off its model.
RECORD = split_record(DT, 7)
_start = split_start


def test_paced_feed_takes_the_record_s_own_time_across_calls():
    u, x = RECORD
    n, dt = 60, 1e-3  # 60 samples at 1 kHz: the last is due 59 ms after the first
    feed = PacedFeed(dt)
    ident = Identifier(DT, _start(), refine="background")
    t0 = time.perf_counter()
    first = feed.push_many(ident, u[:20], x[:20])
    feed.push_many(ident, u[20:n], x[20:n])
    elapsed = time.perf_counter() - t0
    assert elapsed >= (n - 1) * dt
    assert feed.samples == n and first.shape == (20,) and np.all(np.isfinite(first))
    assert 0 <= feed.late_samples <= n and feed.max_late_s >= 0.0


def test_unpaced_sync_is_push_many_and_the_cooperative_schedule_is_a_refine_per_push():
    u, x = RECORD
    sync = Identifier(DT, _start())
    fed = PacedFeed(DT, paced=False).push_many(Identifier(DT, _start()), u, x)
    assert np.array_equal(fed, sync.push_many(u, x))
    coop_feed = feed_for("cooperative", DT)
    assert coop_feed is not None and not coop_feed.paced
    assert coop_feed.refine_intervals == COOPERATIVE_INTERVALS
    fed_coop = coop_feed.push_many(Identifier(DT, _start(), refine="cooperative"), u, x)
    by_hand = Identifier(DT, _start(), refine="cooperative")
    expected = []
    for a, b in zip(u, x):
        expected.append(by_hand.push(a, b))
        by_hand.refine(COOPERATIVE_INTERVALS)
    assert np.array_equal(fed_coop, np.array(expected))
    assert by_hand.status.updates > 0
    assert feed_for("sync", DT) is None
    background = feed_for("background", DT)
    assert background is not None and background.paced and background.refine_intervals == 0


def test_bad_arguments_are_value_errors():
    u, x = RECORD
    for dt in (0.0, -1e-4, float("nan")):
        with pytest.raises(ValueError, match="dt"):
            PacedFeed(dt)
    with pytest.raises(ValueError, match="refine_intervals"):
        PacedFeed(DT, refine_intervals=-1)
    feed = PacedFeed(DT, paced=False)
    ident = Identifier(DT, _start())
    bad = x[:10].copy()
    bad[3] = np.nan
    with pytest.raises(ValueError, match="finite"):
        feed.push_many(ident, u[:10], bad)
    with pytest.raises(ValueError, match="same length"):
        feed.push_many(ident, u[:10], x[:9])
    assert feed.samples == 0 and ident.status.samples == 0
    with pytest.raises(ValueError, match="refine"):
        feed_for("later", DT)


def test_refine_modes_parse():
    assert refine_modes("all") == REFINE_MODES
    assert refine_modes("background,sync") == ("sync", "background")
    for bad in ("", "fast", "all,sync"):
        with pytest.raises(ValueError, match="refine"):
            refine_modes(bad)
