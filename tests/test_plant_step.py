"""boucwen.plant.Bench: the bench stepped sample by sample is the bench of boucwen.plant.measure."""

import math

import numpy as np
import pytest

from boucwen import plant

DT = 1e-4


@pytest.mark.parametrize(
    "settings",
    [
        plant.BenchSettings(),
        plant.BenchSettings(vibration_um=(0.0, 0.0), noise_um=0.004, oversample=3),
        plant.BenchSettings(amplifier_fc_hz=math.inf, creep_gain_um_per_v=(0.0, 0.003, 0.0, 0.001), adc_bits=0),
    ],
)
def test_stepping_a_record_equals_measure(settings):
    _, u, _ = plant.paper_input(DT, ((1.0, 1.0), (10.0, 0.2), (100.0, 0.03), (200.0, 0.02)))
    u = u + 3.0 * np.sin(np.arange(u.size) * 0.37)  # off the smooth path, below 0 V and above 100 V
    rec = plant.measure(u, DT, settings, seed=11)
    bench = plant.Bench(DT, settings, seed=11)
    x = np.empty_like(u)
    u_read = np.empty_like(u)
    x_true = np.empty_like(u)
    for k, v in enumerate(u):
        x[k] = bench.step(float(v))
        u_read[k], x_true[k] = bench.u_read, bench.x_true
    np.testing.assert_array_equal(x, rec.x)  # the same chain, continued from its state
    np.testing.assert_array_equal(x_true, rec.meta["x_true"])
    np.testing.assert_array_equal(u_read, rec.u)
    assert bench.samples == u.size and bench.t == pytest.approx(rec.t[-1])


def test_a_bad_command_is_rejected_and_the_bench_kept():
    bench = plant.Bench(DT, seed=0)
    bench.step(1.0)
    twin = plant.Bench(DT, seed=0)
    twin.step(1.0)
    with pytest.raises(ValueError, match="not finite"):
        bench.step(math.nan)
    assert bench.step(2.0) == twin.step(2.0)
    with pytest.raises(ValueError, match="dt"):
        plant.Bench(0.0)
