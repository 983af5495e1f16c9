"""Generated devices with several records (boucwen.experiments.carried_devices): the
generator's properties without a diagnosis, and one small dev device end to end (slow)."""

import io
import json
import math

import numpy as np
import pytest

from boucwen.effects.base import set_of
from boucwen.experiments import carried_devices as cd
from boucwen.plant import simulate_oversampled

#: One dev device of each kind: generated (0, 8), micromanipulator (2), resonant rig (4),
#: settling drift (6).
DEV_SEEDS = (0, 2, 4, 6, 8)


@pytest.fixture(scope="module")
def devices():
    return {seed: cd.make_device(seed) for seed in DEV_SEEDS}


def test_halves_are_disjoint_and_hold_every_kind():
    dev, held = cd.device_seeds("dev", 40), cd.device_seeds("heldout", 40)
    assert not set(dev) & set(held)
    assert all(s % 2 == 0 and cd.half_of(s) == "dev" for s in dev)
    assert all(s % 2 == 1 and cd.half_of(s) == "heldout" for s in held)
    for seeds in (dev, held):
        assert {cd.kind_of(s) for s in seeds[: cd.CYCLE]} == set(cd.KINDS)
    with pytest.raises(ValueError):
        cd.device_seeds("test", 2)
    with pytest.raises(ValueError):
        cd.make_device(0, kind="bench")


def test_a_seed_makes_one_device():
    a, b = cd.make_device(8), cd.make_device(8)
    assert a.effects == b.effects and a.params.to_array().tolist() == b.params.to_array().tolist()
    for ra, rb in zip(a.records, b.records):
        np.testing.assert_array_equal(ra.u, rb.u)
        np.testing.assert_array_equal(ra.x, rb.x)


def test_kinds_and_their_effects(devices):
    assert [devices[s].kind for s in DEV_SEEDS] == [
        "generated",
        "micromanipulator",
        "resonant_rig",
        "settling_drift",
        "generated",
    ]
    assert set(devices[2].effects) == {"electrostriction"} and devices[2].input_driven
    assert set(devices[4].effects) == {"resonance", "input_lag"} and devices[4].input_driven
    assert 700.0 <= devices[4].effects["resonance"]["fn_hz"] <= 800.0
    assert devices[6].effects == {} and not devices[6].input_driven
    assert all(r.day.drift_tau_s == 5.0 for r in devices[6].records)
    for seed in (0, 8):
        d = devices[seed]
        assert len(d.effects) <= 2 and set(d.effects) <= set(cd.INPUT_DRIVEN)
        assert d.input_driven == bool(d.effects)


def test_records_share_the_device_and_differ_in_their_day_and_excitation(devices):
    for d in devices.values():
        assert 3 <= len(d.records) <= 4
        dts = {r.dt for r in d.records}
        assert len(dts) == 1
        chain = set_of(d.effects)
        for r in d.records:
            # The same device (parameters and effects) under every record.
            np.testing.assert_allclose(r.x_device, simulate_oversampled(d.params, chain, r.u, r.dt, 4), atol=1e-12)
            t = np.arange(r.u.size) * r.dt
            noise = r.x - r.x_device - r.day.at(t)
            assert abs(float(np.std(noise)) - d.noise_um) < 0.1 * d.noise_um
            assert r.u.min() >= 0.0 and r.u.max() <= 100.0
        assert len({r.family for r in d.records}) == len(d.records)
        assert len({r.day.offset_um for r in d.records}) == len(d.records)
        assert len({r.day.trend_um_per_s for r in d.records}) == len(d.records)
        assert len({r.day.drift_um for r in d.records}) == len(d.records)
        assert all(not np.array_equal(a.u, b.u) for a, b in zip(d.records, d.records[1:]))


def test_records_start_and_end_at_rest(devices):
    for d in devices.values():
        rest = max(10, round(cd.REST_S / d.records[0].dt))
        for r in d.records:
            assert np.ptp(r.u[:rest]) == 0.0, (d.label, r.family)
            assert np.ptp(r.u[-rest:]) == 0.0, (d.label, r.family)
            assert np.ptp(r.u) > 10.0


@pytest.mark.slow
def test_one_dev_device_end_to_end(tmp_path):
    out = io.StringIO()
    doc = cd.run("dev", 1, workers=1, out=out, progress=False)
    (row,) = doc["devices"]
    assert row["seed"] == 0 and row["half"] == "dev" and row["kind"] == "generated"
    assert len(row["records"]) == len(cd.make_device(0).records) - 1
    for r in row["records"]:
        assert r["base_rms_um"] > 0 and math.isfinite(r["ratio"])
        assert r["ratio"] == pytest.approx(r["returned_rms_um"] / r["base_rms_um"])
        assert r["true_rms_um"] > 0
    assert row["worst_ratio"] == max(r["ratio"] for r in row["records"])
    assert row["passed"] == (row["worst_ratio"] <= cd.NEVER_WORSE and row["input_gain"] is not False)
    assert "dev:" in out.getvalue() and "seed" in out.getvalue()
    path = tmp_path / "out.json"
    cd.main(["--devices", "1", "--json", str(path)])
    assert json.loads(path.read_text())["halves"][0]["devices"][0]["seed"] == 0
