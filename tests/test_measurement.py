"""The measurement chain's output end (boucwen.measurement): the FIR design against
SciPy's, the decimation against a direct convolution, the record-rate equivalent of a
decimation against the decimation itself, and the filter's argument checks."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from boucwen.measurement import OutputFilter, check_input, decimate_fir, decimation_filter, fir_lowpass


@pytest.mark.parametrize("factor", [2, 5])
def test_the_lowpass_is_the_window_methods_hamming_design(factor):
    np.testing.assert_allclose(fir_lowpass(30, 1.0 / factor), signal.firwin(31, 1.0 / factor), atol=1e-15)


def test_decimation_filters_with_its_delay_compensated_and_keeps_every_rth_sample():
    x = np.random.default_rng(0).normal(size=500)
    taps = signal.firwin(31, 0.2)
    # The reflected ends (2·x[0] − x[i]) and the centred convolution, by hand.
    ext = np.concatenate([2 * x[0] - x[15:0:-1], x, 2 * x[-1] - x[-2:-17:-1]])
    direct = np.array([np.dot(taps, ext[k : k + 31][::-1]) for k in range(x.size)])
    np.testing.assert_allclose(decimate_fir(x, 5), direct[::5], atol=1e-13)


def test_the_record_rate_equivalent_matches_the_decimation_within_its_band():
    stages = (2, 2, 5)
    fast_rate = 15000.0
    t = np.arange(20 * 3000) / fast_rate
    # Content up to 280 Hz, below the equivalent's band (0.4 of 750 Hz).
    x = sum(np.sin(2 * np.pi * f * t + f) for f in (3.0, 35.0, 90.0, 150.0, 280.0))
    decimated = x
    for r in stages:
        decimated = decimate_fir(decimated, r)
    equivalent = decimation_filter(stages).apply(x[::20])
    inner = slice(200, -200)
    assert np.max(np.abs(decimated - equivalent)[inner]) < 2e-8
    # The filter itself matters: its response departs from 1 by 1e-3 at 150 Hz.
    assert np.max(np.abs(decimated - x[::20])[inner]) > 1e-3
    gain = decimation_filter(stages).gain([35.0, 150.0, 375.0], 1 / 750.0)
    np.testing.assert_allclose(gain[:2], [1 - 2.383e-4, 1 + 1.258e-3], atol=2e-6)


def test_the_filter_applies_to_each_column_and_checks_its_arguments():
    f = OutputFilter((0.25, 0.5, 0.25), 1, "smoothing")
    y = np.arange(10.0) ** 2
    both = f.apply(np.column_stack([y, 2 * y]))
    np.testing.assert_allclose(both[:, 1], 2 * f.apply(y))
    # A straight line passes unchanged, ends included (point reflection keeps it).
    np.testing.assert_allclose(f.apply(np.arange(5.0)), np.arange(5.0))
    with pytest.raises(ValueError, match="center"):
        OutputFilter((1.0, 2.0), 2)
    with pytest.raises(ValueError, match="static gain"):
        OutputFilter((1.0, -1.0), 0)
    with pytest.raises(ValueError, match="taps"):
        OutputFilter((), 0)
    with pytest.raises(ValueError, match="hold"):
        check_input("spline")
    assert check_input("hold") == "hold"
