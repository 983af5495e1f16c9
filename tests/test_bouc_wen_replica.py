"""The replica of the Bouc–Wen benchmark (boucwen.experiments.bouc_wen_replica): the fit
with the benchmark's measurement chain recovers the true parameters within their standard
errors and predicts the noise-free steady-state test multisine within 2e-7 m; without
the chain (force linear between samples, no filter on y) it does neither."""

from __future__ import annotations

import numpy as np
import pytest

from boucwen.experiments import bouc_wen_replica as replica
from boucwen.experiments.bouc_wen_benchmark import benchmark_chain
from boucwen.oscillator import OscillatorParams, fit


@pytest.fixture(scope="module")
def records() -> replica.Replica:
    return replica.replica()


def test_the_replicas_noise_passed_the_decimation(records):
    # 8e-6 m at 15 kHz, the decimation's filter takes off its top (the shared training
    # record's noise, estimated from its periods, is 7.39e-6 m).
    assert 7.0e-6 < records.noise_rms_m < 7.8e-6
    assert records.force.size == replica.PERIODS * replica.PERIOD
    assert np.std(records.force) == pytest.approx(replica.RMS_N, rel=0.01)


def test_the_fit_with_the_chain_recovers_the_parameters_and_predicts_the_test_record(records):
    chained = fit(records.force, records.y, records.dt, input="bandlimited", periodic=True, output=benchmark_chain())
    deviations = replica.deviations(chained, OscillatorParams.benchmark())
    assert max(abs(d) for d in deviations.values()) <= replica.SE_LIMIT, deviations
    test_rms = float(
        np.sqrt(np.mean((replica.steady_prediction(chained, records.test_force, records.dt) - records.test_y) ** 2))
    )
    assert test_rms <= replica.TEST_RMS_LIMIT_M, test_rms


def test_without_the_chain_the_fit_is_biased_and_the_test_record_missed(records):
    plain = fit(records.force, records.y, records.dt)
    deviations = replica.deviations(plain, OscillatorParams.benchmark())
    assert abs(deviations["m"]) > 10 * replica.SE_LIMIT
    predicted = replica.steady_prediction(plain, records.test_force, records.dt)
    assert np.sqrt(np.mean((predicted - records.test_y) ** 2)) > 10 * replica.TEST_RMS_LIMIT_M
