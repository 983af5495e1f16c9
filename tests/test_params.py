"""boucwen.Params: validation, repr round trip, equality and hash, conversions, pickle, immutability."""

import math
import pickle

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import boucwen
from boucwen import Params

NAMES = ["kv", "x0", "A", "beta", "gamma", "n", "delta"]
PAPER = dict(kv=0.19, x0=0.015, A=-0.072, beta=0.020, gamma=-0.019, n=1.52, delta=0.0075)

finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)
positive = st.floats(min_value=1e-6, max_value=10.0, allow_nan=False, allow_infinity=False)
params_st = st.builds(Params, kv=finite, x0=finite, A=finite, beta=finite, gamma=finite, n=positive, delta=finite)


def test_fields_and_names():
    p = Params(**PAPER)
    assert [getattr(p, k) for k in NAMES] == list(PAPER.values())
    assert list(Params.names) == NAMES
    assert p == Params.paper_1hz()


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_value_raises_value_error_naming_it(name, bad):
    with pytest.raises(ValueError, match=rf"\b{name}\b"):
        Params(**{**PAPER, name: bad})


@pytest.mark.parametrize("n", [0.0, -1.0, -1e-300])
def test_non_positive_n_raises(n):
    with pytest.raises(ValueError, match=r"\bn\b.*> 0"):
        Params(**{**PAPER, "n": n})


def test_missing_or_unknown_argument_is_a_type_error():
    with pytest.raises(TypeError):
        Params(**{k: v for k, v in PAPER.items() if k != "delta"})
    with pytest.raises(TypeError):
        Params(**PAPER, creep=1.0)


@given(params_st)
def test_repr_round_trips(p):
    assert eval(repr(p), {"Params": Params}) == p
    assert repr(p).startswith("Params(kv=")


@given(params_st)
def test_equal_values_are_equal_and_hash_alike(p):
    q = Params.from_array(p.to_array())
    assert q == p
    assert (q != p) is False  # __ne__ agrees with __eq__
    assert hash(q) == hash(p)
    assert len({p, q}) == 1


def test_inequality_and_zero_signs():
    p = Params(**PAPER)
    assert p != p.replace(delta=0.0076)
    assert p != "not params"
    # -0.0 == 0.0, so they must hash alike.
    a, b = p.replace(x0=0.0), p.replace(x0=-0.0)
    assert a == b and hash(a) == hash(b)


@given(params_st)
def test_array_round_trip(p):
    arr = p.to_array()
    assert isinstance(arr, np.ndarray) and arr.dtype == np.float64 and arr.shape == (7,)
    assert arr.tolist() == [getattr(p, k) for k in NAMES]
    assert Params.from_array(arr) == p
    assert Params.from_array(list(arr)) == p
    kv = p.kv
    arr[0] = kv + 1.0  # a copy: changing it leaves p alone
    assert p.kv == kv and p.to_array()[0] == kv


@given(params_st)
def test_dict_round_trip(p):
    d = p.to_dict()
    assert list(d) == NAMES
    assert Params.from_dict(d) == p
    assert Params(**d) == p


def test_from_array_and_from_dict_reject_bad_input():
    with pytest.raises(ValueError, match="7"):
        Params.from_array([1.0] * 6)
    with pytest.raises(ValueError, match=r"\bgamma\b"):
        Params.from_array([0.19, 0.0, -0.07, 0.02, math.nan, 1.5, 0.0])
    with pytest.raises(ValueError, match="1-D"):
        Params.from_array(np.ones((7, 1)))
    with pytest.raises(TypeError):
        Params.from_array("1234567")
    with pytest.raises(KeyError, match="delta"):
        Params.from_dict({k: v for k, v in PAPER.items() if k != "delta"})
    with pytest.raises(ValueError, match="creep"):
        Params.from_dict({**PAPER, "creep": 1.0})
    with pytest.raises(ValueError, match=r"\bn\b"):
        Params.from_dict({**PAPER, "n": -1.0})


def test_replace_validates_and_copies():
    p = Params(**PAPER)
    q = p.replace(n=1.6, A=-0.1)
    assert (q.n, q.A, q.kv) == (1.6, -0.1, p.kv)
    assert p.n == 1.52
    with pytest.raises(ValueError, match=r"\bn\b"):
        p.replace(n=0.0)
    with pytest.raises(ValueError, match="creep"):
        p.replace(creep=1.0)


@given(params_st)
def test_pickle_round_trip(p):
    for protocol in range(pickle.HIGHEST_PROTOCOL + 1):
        q = pickle.loads(pickle.dumps(p, protocol=protocol))
        assert q == p and type(q) is Params


@pytest.mark.parametrize("name", NAMES)
def test_immutable(name):
    p = Params(**PAPER)
    with pytest.raises(AttributeError):
        setattr(p, name, 1.0)
    with pytest.raises(AttributeError):
        p.new_attribute = 1.0
    assert p == Params(**PAPER)


def test_public_names():
    assert boucwen.Params is Params
    assert isinstance(boucwen.__version__, str) and boucwen.__version__
