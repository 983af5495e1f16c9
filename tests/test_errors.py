"""Named exceptions: each realistic bad input raises its own ``ValueError`` subclass
with a precise message, and an identifier that refused an input goes on as if the
input had never been given."""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest

import boucwen
from boucwen import (
    CorruptSnapshot,
    Identifier,
    InvalidConfig,
    InvalidParams,
    InvalidRecord,
    LengthMismatch,
    Params,
)

DT = 1e-4
NAMED = (InvalidParams, InvalidConfig, InvalidRecord, CorruptSnapshot, LengthMismatch)


def _record(n: int = 3000) -> tuple[np.ndarray, np.ndarray]:
    u = np.asarray(boucwen.paper_input(DT, 0.05))[:n]
    x, _ = boucwen.simulate(Params.paper_1hz(), u, DT)
    return u, x + 1e-3 * np.random.default_rng(7).standard_normal(u.size)


@pytest.mark.parametrize("cls", NAMED)
def test_every_named_exception_is_a_documented_value_error_of_the_package(cls: type[ValueError]) -> None:
    assert issubclass(cls, ValueError)
    assert cls.__module__ == "boucwen"
    assert getattr(boucwen, cls.__name__) is cls
    assert cls.__name__ in boucwen.__all__
    assert cls.__doc__ is not None and len(cls.__doc__) > 60  # says when it is raised
    others = [c for c in NAMED if c is not cls]
    assert not any(issubclass(cls, other) for other in others)


def _twin_pair(method: str) -> tuple[Identifier, Identifier]:
    make = {
        "horizon": lambda: Identifier(DT, Params.paper_1hz()),
        "rpem": lambda: Identifier.rpem(DT, Params.paper_1hz()),
        "paper": lambda: Identifier.paper(DT, 200, Params.paper_1hz()),
    }[method]
    return make(), make()


@pytest.mark.parametrize("method", ["horizon", "rpem", "paper"])
def test_a_refused_input_leaves_the_identifier_usable_and_unchanged(method: str) -> None:
    u, x = _record()
    ident, twin = _twin_pair(method)
    ident.push_many(u[:1000], x[:1000])
    twin.push_many(u[:1000], x[:1000])
    with pytest.raises(InvalidRecord, match=r"sample u = NaN is not finite; the sample was rejected"):
        ident.push(float("nan"), 0.1)
    with pytest.raises(InvalidRecord, match=r"sample x = inf is not finite"):
        ident.push(1.0, float("inf"))
    bad = x[1000:1100].copy()
    bad[37] = np.nan
    with pytest.raises(InvalidRecord, match=r"sample x = NaN"):
        ident.push_many(u[1000:1100], bad)
    with pytest.raises(LengthMismatch, match=r"x \(same length as u\): expected length 100, found 99"):
        ident.push_many(u[1000:1100], x[1000:1099])
    with pytest.raises(InvalidRecord, match=r"u must be 1-D, got shape \(10, 10\)"):
        ident.push_many(u[1000:1100].reshape(10, 10), x[1000:1100].reshape(10, 10))
    restore, args = ident.__reduce__()
    with pytest.raises(CorruptSnapshot, match=r"corrupt snapshot at byte \d+"):
        restore(args[0][:-1], *args[1:])
    a = ident.push_many(u[1000:], x[1000:])
    b = twin.push_many(u[1000:], x[1000:])
    np.testing.assert_array_equal(a.view(np.uint64), b.view(np.uint64))
    assert ident.params == twin.params


def test_truncated_pickles_raise_corrupt_snapshot() -> None:
    u, x = _record(500)
    ident = Identifier.rpem(DT, Params.paper_1hz())
    ident.push_many(u, x)
    restore, (data,) = ident.__reduce__()
    with pytest.raises(CorruptSnapshot, match=r"corrupt snapshot at byte \d+: "):
        restore(data[:10])
    assert restore(data).params == ident.params
    model, twin = boucwen.Model(Params.paper_1hz(), DT), boucwen.Model(Params.paper_1hz(), DT)
    model.step(1.0)
    twin.step(1.0)
    state = model.__getstate__()
    with pytest.raises(CorruptSnapshot, match=r"corrupt snapshot at byte \d+: "):
        model.__setstate__(state[:-2])
    assert model.step(2.0) == twin.step(2.0)  # the refused state left the model as it was
    with pytest.raises(ValueError, match="snapshot"):  # still caught as a ValueError
        restore(data[:-3])
    assert pickle.loads(pickle.dumps(ident)).params == ident.params


def test_invalid_parameters_raise_invalid_params() -> None:
    with pytest.raises(InvalidParams, match=r"invalid parameter n = -1: "):
        Params.paper_1hz().replace(n=-1.0)
    with pytest.raises(InvalidParams, match=r"invalid parameter kv = NaN: must be finite"):
        Params.from_array([float("nan"), 0, 1, 1, 0.5, 1.5, 0])
    with pytest.raises(InvalidParams, match=r"expected 7 values .*, got 3"):
        Params.from_array([1.0, 2.0, 3.0])
    with pytest.raises(InvalidParams, match=r"unknown parameter zeta"):
        Params.from_dict({**Params.paper_1hz().to_dict(), "zeta": 1.0})
    with pytest.raises(InvalidParams, match=r"input_lag: unknown parameter 'tau'"):
        boucwen.InputLag.from_dict({"tau": 1.0})
    with pytest.raises(InvalidParams, match=r'unknown effect "hum"; expected one of \["creep"'):
        boucwen.EffectSet.from_dict({"hum": {}})


def test_invalid_configuration_raises_invalid_config() -> None:
    p = Params.paper_1hz()
    with pytest.raises(InvalidConfig, match=r"invalid dt = -0.0001: the sampling interval must be finite and > 0"):
        Identifier.rpem(-DT, p)
    with pytest.raises(InvalidConfig, match=r"invalid forgetting = 2"):
        boucwen.RpemConfig(forgetting=2.0)
    with pytest.raises(InvalidConfig, match=r"invalid window = 3: the window holds 16 to 10000000 samples"):
        Identifier.paper(DT, 3, p)
    with pytest.raises(InvalidConfig, match=r"invalid window = 3"):
        boucwen.Bank.paper(2, DT, 3, p)
    with pytest.raises(
        InvalidConfig, match=r'invalid refine = "later": expected "sync", "cooperative" or "background"'
    ):
        Identifier(DT, p, refine="later")
    with pytest.raises(InvalidConfig, match=r"invalid channels = 0"):
        boucwen.Bank(0, DT, p)
    with pytest.raises(InvalidConfig, match=r"n_starts must be an integer >= 1, got 0"):
        boucwen.fit(*_record(200), DT, n_starts=0)


def test_bad_records_raise_invalid_record(tmp_path: Path) -> None:
    u, x = _record(200)
    bad = x.copy()
    bad[17] = np.nan
    with pytest.raises(InvalidRecord, match=r"x\[17\] is nan; all samples must be finite \(1 non-finite\)"):
        boucwen.fit(u, bad, DT)
    with pytest.raises(InvalidRecord, match=r"u and x must have the same length, got 200 and 199"):
        boucwen.fit(u, x[:-1], DT)
    with pytest.raises(InvalidRecord, match=r"u is empty"):
        boucwen.io.Record(t=[], u=[], x=[], dt=DT)
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    with pytest.raises(InvalidRecord, match=r"empty\.csv: empty file, expected a header line"):
        boucwen.io.read_csv(empty)
    wrong = tmp_path / "wrong.csv"
    wrong.write_text("t,u,y\n0,0,0\n0.1,1,1\n0.2,2,2\n")
    with pytest.raises(InvalidRecord, match=r"wrong\.csv: line 1: missing column 'x' \(found: 't', 'u', 'y'"):
        boucwen.io.read_csv(wrong)
    nan = tmp_path / "nan.csv"
    nan.write_text("t,u,x\n0,0,0\n0.1,1,nan\n0.2,2,2\n")
    with pytest.raises(InvalidRecord, match=r"nan\.csv: line 3: column 'x': non-finite value 'nan'"):
        boucwen.io.read_csv(nan)
    with pytest.raises(InvalidRecord, match=r"no such file"):
        boucwen.io.read_csv(tmp_path / "absent.csv")
    with pytest.raises(InvalidConfig, match=r"dt must be finite and > 0 s, got 0.0"):
        boucwen.io.read_csv(wrong, dt=0.0)
