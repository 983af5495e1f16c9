"""The white measurement-noise level of a displacement record, from x alone
(:func:`noise_level`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..checks import FloatArray

__all__ = ["MAX_DIFF_ORDER", "NoiseLevel", "noise_level"]

#: Highest order of the difference operator used by :func:`noise_level`.
MAX_DIFF_ORDER = 4
#: Asymptotic efficiency of the MAD scale estimator against the standard deviation
#: for Gaussian data (its variance is 1/0.368 times larger).
_MAD_EFFICIENCY = 0.3675


@dataclass(frozen=True)
class NoiseLevel:
    """The noise level of a record and how it was obtained.

    Attributes:
        sigma_um: standard deviation of the white measurement noise [µm].
        order: order k of the difference operator that gave it (0: quantisation floor).
        dof: equivalent degrees of freedom of σ̂² (its variance is 2σ⁴/dof).
        estimator: one sentence naming the estimator.
    """

    sigma_um: float
    order: int
    dof: float
    estimator: str


def _binomial_filter(k: int) -> FloatArray:
    """Coefficients of the k-th difference operator (−1)^j·C(k, j)."""
    return np.array([(-1.0) ** j * math.comb(k, j) for j in range(k + 1)])


def noise_level(x: FloatArray) -> NoiseLevel:
    """White measurement-noise level of a displacement record, from x alone.

    Estimator: for k = 1 … 4, the k-th difference Δᵏx of the samples is taken and
    its spread measured by the median absolute deviation (MAD) scaled to a standard
    deviation (×1.4826) and divided by √C(2k, k), the gain of Δᵏ on white noise; σ̂ is
    the smallest of the four.

    Assumptions: the noise is white (independent samples) and Gaussian-like; the
    displacement itself is smooth on the scale of a few samples, so that Δᵏ removes
    it (Δᵏ annihilates polynomials of degree < k; a sine of frequency f is scaled by
    (2·sin(π·f·dt))ᵏ), except at a minority of samples (steps, fast bursts) which the
    median ignores. The smallest of the four is the one least inflated by the
    signal; taking the minimum biases σ̂ low by about its own scatter (≈ 1.2/√N).
    A record whose differences are mostly zero (coarse quantisation) gets the
    quantisation floor q/√12, q the smallest non-zero |Δx| (``order`` 0).
    """
    n = x.size
    best = NoiseLevel(math.inf, 1, 1.0, "")
    for k in range(1, MAX_DIFF_ORDER + 1):
        if n - k < 8:
            break
        d = np.diff(x, k)
        mad = float(np.median(np.abs(d - np.median(d))))
        sigma = 1.4826 * mad / math.sqrt(math.comb(2 * k, k))
        if sigma < best.sigma_um:
            c = _binomial_filter(k)
            acf = np.correlate(c, c, mode="full")[k:] / float(c @ c)
            inflation = 1.0 + 2.0 * float(np.sum(acf[1:] ** 2))
            dof = max(1.0, _MAD_EFFICIENCY * (n - k) / inflation)
            best = NoiseLevel(
                sigma,
                k,
                dof,
                f"MAD of the order-{k} differences of x, scaled by 1.4826/√C({2 * k},{k}) "
                f"(smallest over orders 1…{MAX_DIFF_ORDER})",
            )
    if not best.sigma_um > 0:
        steps = np.abs(np.diff(x))
        steps = steps[steps > 0]
        q = float(steps.min()) if steps.size else 0.0
        best = NoiseLevel(
            q / math.sqrt(12.0), 0, max(1.0, float(steps.size)), "quantisation floor q/√12 (differences mostly zero)"
        )
    return best
