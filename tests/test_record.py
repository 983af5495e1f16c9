"""boucwen.record: the one check of (u, x, dt), and the record's parts."""

import numpy as np
import pytest

from boucwen import io
from boucwen.record import Record, validate_record


def test_validate_record_checks_once_and_builds_the_times():
    rec = validate_record([0, 1, 2, 3], [0.0, 0.5, 1.0, 1.5], 0.01, name="r")
    assert rec.u.dtype == rec.x.dtype == rec.t.dtype == np.float64
    np.testing.assert_allclose(rec.t, [0.0, 0.01, 0.02, 0.03], rtol=0, atol=1e-15)
    assert rec.dt == 0.01 and rec.name == "r" and len(rec) == 4
    assert rec.duration_s == pytest.approx(0.03)
    assert io.Record is Record  # the same class from both modules


@pytest.mark.parametrize(
    "u, x, dt, exc, words",
    [
        ([0.0, 1.0], [0.0], 1e-3, ValueError, "same length"),
        ([0.0, np.nan], [0.0, 1.0], 1e-3, ValueError, r"u\[1\]"),
        ([0.0, 1.0], [0.0, np.inf], 1e-3, ValueError, r"x\[1\]"),
        (np.zeros((2, 2)), np.zeros((2, 2)), 1e-3, ValueError, "1-D"),
        ([], [], 1e-3, ValueError, "empty"),
        (["a"], [0.0], 1e-3, TypeError, "real numbers"),
        ([0.0, 1.0], [0.0, 1.0], 0.0, ValueError, "dt"),
        ([0.0, 1.0], [0.0, 1.0], "1e-3", TypeError, "dt"),
        ([0.0, 1.0], [0.0, 1.0], True, TypeError, "dt"),
    ],
)
def test_validate_record_rejects_bad_data_with_a_precise_message(u, x, dt, exc, words):
    with pytest.raises(exc, match=words):
        validate_record(u, x, dt)


def test_a_record_built_directly_is_checked_too():
    with pytest.raises(ValueError, match="t has 2 samples"):
        Record(t=np.arange(2.0), u=np.zeros(3), x=np.zeros(3), dt=1.0)
    with pytest.raises(TypeError, match="dt"):
        Record(t=np.arange(3.0), u=np.zeros(3), x=np.zeros(3), dt=None)


def test_parts_are_views_with_the_right_samples_and_interval():
    u = np.arange(10.0)
    rec = validate_record(u, 2 * u, 0.1)
    head = rec.part(0, 7)
    assert len(head) == 7 and head.dt == rec.dt
    assert np.shares_memory(head.u, rec.u)
    np.testing.assert_array_equal(head.x, 2 * u[:7])
    tail = rec.part(7)
    np.testing.assert_array_equal(tail.t, rec.t[7:])
    with pytest.raises(ValueError, match="empty"):
        rec.part(10)

    coarse = rec.decimated(3)
    np.testing.assert_array_equal(coarse.u, [0.0, 3.0, 6.0, 9.0])
    assert coarse.dt == pytest.approx(0.3)
    with pytest.raises(ValueError, match="factor"):
        rec.decimated(0)

    # A sensor delay of 2 samples taken out: u[k] is paired with x[k + 2].
    shifted = rec.realigned(2)
    assert len(shifted) == 8
    np.testing.assert_array_equal(shifted.u, u[:8])
    np.testing.assert_array_equal(shifted.x, 2 * u[2:])
    np.testing.assert_array_equal(shifted.t, rec.t[:8])
    with pytest.raises(ValueError, match="delay_samples"):
        rec.realigned(10)
