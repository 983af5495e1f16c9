"""The recommended identifier's window pass beside push: ``refine="sync"`` (the
default, the predictions of earlier releases), ``"cooperative"`` (``ident.refine``)
and ``"background"`` (a worker thread)."""

import copy
import pickle
import time

import numpy as np
import pytest

from boucwen import Identifier
from conftest import split_record, split_start

DT = 1e-4


@pytest.fixture(scope="module")
def record():
    return split_record(DT, 5)


_start = split_start


def test_sync_is_the_default_and_refine_does_nothing(record):
    u, x = record
    default, sync = Identifier(DT, _start()), Identifier(DT, _start(), refine="sync")
    assert default.refine_mode == sync.refine_mode == "sync"
    pred = default.push_many(u, x)
    for k in range(u.size):
        assert sync.push(u[k], x[k]) == pred[k]
        assert sync.refine(100) == 0
    assert Identifier.rpem(DT, _start()).refine_mode is None
    assert Identifier.rpem(DT, _start()).refine(10) == 0


def test_cooperative_is_reproducible_and_pickles(record):
    u, x = record
    a = Identifier(DT, _start(), refine="cooperative")
    b = Identifier(DT, _start(), refine="cooperative")
    pa, pb = [], []
    for k in range(u.size):
        pa.append(a.push(u[k], x[k]))
        pb.append(b.push(u[k], x[k]))
        budget = 40 if k % 3 else 0
        assert a.refine(budget) == b.refine(budget)
        if k == 20_000:
            c = pickle.loads(pickle.dumps(a))
            d = copy.copy(a)
            assert c.refine_mode == d.refine_mode == "cooperative"
            np.testing.assert_array_equal(c.push_many(u[k + 1 :], x[k + 1 :]), d.push_many(u[k + 1 :], x[k + 1 :]))
    assert pa == pb
    status = a.status
    assert status.updates > 10
    assert status.behind_samples >= 0 and status.behind_s == pytest.approx(status.behind_samples * DT)
    assert a.params.to_dict() != _start().to_dict()


def test_cooperative_without_refine_is_the_starting_model(record):
    u, x = record
    ident = Identifier(DT, _start(), refine="cooperative")
    ahead = ident.forecast(u)
    np.testing.assert_array_equal(ident.push_many(u, x), ahead)
    assert ident.status.behind_samples == u.size
    assert ident.refine(10**12) > 0
    assert ident.status.updated and ident.params.to_dict() != _start().to_dict()


def test_background_push_never_waits_and_adopts(record):
    u, x = record
    ident = Identifier(DT, _start(), refine="background")
    assert ident.refine_mode == "background" and ident.method == "horizon"
    assert ident.refine(100) == 0
    updates = 0
    for k in range(u.size):
        assert np.isfinite(ident.push(u[k], x[k]))
        updates = max(updates, ident.status.updates)
        if k % 500 == 0:
            time.sleep(0.002)  # room for the worker on a busy machine
    assert np.isfinite(ident.h)
    c = pickle.loads(pickle.dumps(ident))
    assert c.refine_mode == "background"
    assert type(c.status) is type(ident.status)
    ident.reset()
    assert ident.params.to_dict() == _start().to_dict()


def test_bad_refine_mode_is_a_value_error():
    with pytest.raises(ValueError, match="refine"):
        Identifier(DT, _start(), refine="later")
    with pytest.raises(ValueError, match="max_intervals"):
        Identifier(DT, _start(), refine="cooperative").refine(-1)
