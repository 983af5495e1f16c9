"""Shared test helpers, and the hypothesis profiles.

Property tests run under a named hypothesis profile, chosen by the environment
variable ``HYPOTHESIS_PROFILE``:

* ``ci`` (the default, used by ``scripts/test.sh`` and ``.ci/run``): derandomized, so
  the same examples are drawn on every run and every machine; no example database.
* ``explore``: random seeds and the example database, for local runs that look for
  new counter-examples (``HYPOTHESIS_PROFILE=explore python -m pytest tests``). Every
  counter-example found this way is kept in its test as an explicit ``@example``.

Slow tests carry the marker ``slow`` (``bash scripts/test.sh --slow`` runs them, and CI
does; ``bash scripts/test.sh`` leaves them out): a test marked so, and every test of the
modules of :data:`SLOW_MODULES`.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import settings

import boucwen
from boucwen.record import Record, validate_record

settings.register_profile("ci", derandomize=True, database=None, print_blob=True)
settings.register_profile("explore", derandomize=False, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

#: Test modules whose every test runs the diagnosis on whole records and judges its
#: statistics (the suite, the solvers' agreement, the measured records, the other model
#: structure, the screen against the refits, the judge's calibration): minutes each on
#: two cores, so all of them are ``slow``, whatever tests the modules hold. The judge's
#: own tests (tests/test_judge.py, tests/test_search.py) run on constructed numbers and
#: small records in seconds, and stay in the quick command.
SLOW_MODULES = frozenset(
    {
        "test_convergence.py",
        "test_diagnose.py",
        "test_calibration.py",
        "test_diagnosis_suite.py",
        "test_measured.py",
        "test_screen.py",
        "test_structure.py",
    }
)


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Marks every test of :data:`SLOW_MODULES` ``slow`` (before ``-m`` selects)."""
    for item in items:
        if item.path.name in SLOW_MODULES:
            item.add_marker(pytest.mark.slow)


#: Counter-examples found by property tests, kept as files (tests/regressions/).
REGRESSIONS = Path(__file__).parent / "regressions"


def regression_case(name: str) -> dict[str, Any]:
    """The counter-example ``tests/regressions/<name>.json``."""
    with (REGRESSIONS / f"{name}.json").open() as f:
        case: dict[str, Any] = json.load(f)
    return case


#: One of each of the first five effects of the vocabulary (whose fit layout and starts
#: the tests pin), as ``EffectSet`` keyword arguments.
EVERY_EFFECT: dict[str, Any] = dict(
    creep={"tau_s": [0.01, 0.5], "gain_um_per_v": [0.003, 0.004]},
    input_lag={"fc_hz": 80.0},
    resonance={"fn_hz": 150.0, "zeta": 0.1},
    drift={"rate_um_per_s": 0.2},
    delay={"samples": 2},
)

#: One of each effect of the vocabulary, in signal-chain order (simulable at dt = 1 ms).
WHOLE_VOCABULARY: dict[str, Any] = dict(
    creep=EVERY_EFFECT["creep"],
    input_lag=EVERY_EFFECT["input_lag"],
    gain_drift={"rate_per_s": 0.01},
    electrostriction={"epsilon_per_um": 0.004},
    resonance=EVERY_EFFECT["resonance"],
    resonance2={"fn_hz": 300.0, "zeta": 0.2},
    drift=EVERY_EFFECT["drift"],
    delay=EVERY_EFFECT["delay"],
    pickup={"line_hz": 50.0, "sin_um": [0.1, 0.0], "cos_um": [0.02, 0.01]},
    saturation={"min_um": -1.0, "max_um": 30.0},
)


def make_identifier(
    method: str, dt: float, window: Any, init: Any, h0: float = 0.0, **options: Any
) -> boucwen.Identifier:
    """An identifier of `method` ("horizon", "paper" or "rpem") with the options of its config
    given by name; `window` is the paper method's N (not used by "rpem"); `effects`
    goes to "rpem"."""
    if method == "paper":
        config = boucwen.PaperConfig(**options) if options else None
        return boucwen.Identifier.paper(dt, window, init, h0, config=config)
    if method == "horizon":
        config = boucwen.HorizonConfig(**options) if options else None
        return boucwen.Identifier.horizon(dt, init, h0, config=config)
    if method == "rpem":
        effects = options.pop("effects", None)
        config = boucwen.RpemConfig(**options) if options else None
        return boucwen.Identifier.rpem(dt, init, h0, config=config, effects=effects)
    raise ValueError(f"invalid method = {method!r}: expected 'horizon', 'paper' or 'rpem'")


def split_record(dt: float, seed: int) -> tuple[Any, Any]:
    """The paper's input for 0.05 s of each frequency at interval `dt` [s] and the paper's
    model's displacement [µm] with 2 nm of seeded noise: a record for the split identifier's
    tests (``refine``)."""
    u = boucwen.paper_input(dt, 0.05)
    x, _ = boucwen.simulate(boucwen.Params.paper_1hz(), u, dt)
    return u, x + 0.002 * np.random.default_rng(seed).standard_normal(u.size)


def split_start() -> boucwen.Params:
    """Starting values off the paper's, so that the estimates move."""
    return boucwen.Params.paper_1hz().replace(kv=0.15, beta=0.03)


def reference_pair(params: Any, u: Any, dt: float, substeps: int, **options: Any) -> tuple[np.ndarray, float, float]:
    """``boucwen.reference.simulate`` at ``substeps`` and twice as many RK4 steps per
    sample: returns ``(x, h_final)`` of the finer one and ``max |x_m − x_2m|`` (over x and
    h_final) [µm], which bounds the finer one's error wherever halving the step at least
    halves the error (RK4: by 16 where the solution is smooth, still by more than 2
    across the kinks of |h|^n at h = 0 and of u̇ at the samples)."""
    from boucwen import reference

    x_m, h_m = reference.simulate(params, u, dt, substeps=substeps, **options)
    x_2m, h_2m = reference.simulate(params, u, dt, substeps=2 * substeps, **options)
    error = max(float(np.max(np.abs(x_m - x_2m), initial=0.0)), abs(h_m - h_2m))
    return x_2m, h_2m, error


@pytest.fixture(scope="session")
def drift_record() -> Record:
    """A small constructed record for the rules of the diagnosis: the paper's 1 Hz model
    with a drift of 2 µm/s under a sine with square steps (1 kHz, 2 s, 5 nm of noise)."""
    rng = np.random.default_rng(0)
    dt, n = 1e-3, 2000
    t = np.arange(n) * dt
    u = 50.0 + 40.0 * np.sin(2 * np.pi * 3 * t) + 10.0 * np.sign(np.sin(2 * np.pi * 0.7 * t))
    drift = boucwen.EffectSet(drift={"rate_um_per_s": 2.0})
    x = boucwen.simulate_extended(boucwen.Params.paper_1hz(), drift, u, dt) + rng.normal(0.0, 0.005, n)
    return validate_record(u, x, dt)
