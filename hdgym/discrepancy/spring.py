"""The spring-curve comparison of locked-output records.

On a locked output the motor angle is ratio x torsion, and the torsion against the torque
the joint transmits is the spring curve: a hardening spring bends it, hysteresis opens it
into a loop. On the time channels a base fit's linear stiffness absorbs most of the
hardening (what is left is far below the channels' noise), but the curve itself stays
bent: averaged over many samples of the same torque, the noise goes and the bend stays.

The comparison (:class:`.problem.Problem` with ``compare = "spring"``) replaces each
channel's residual by its mean over bins of the measured torque, taken apart by the
direction in which the torque moves (:data:`BINS` quantile bins per direction), so the
NMSE is that of the binned spring curve (what the model gets wrong as a function of
torque and direction) and the least-squares cost fits it. The noise of a bin mean is the
channel's noise divided by the independent samples in the bin (:func:`spring_noise`).
Effects that this comparison reveals say so (``"spring"`` in
:attr:`.effect.Effect.compare`).
"""

from __future__ import annotations

import numpy as np

from . import residuals as R

BINS = 12
"""Quantile bins of the measured torque per direction of its change."""
MIN_SHARE = 0.02
"""Least share of the compared samples a bin must hold to be kept."""


def spring_bins(torque: np.ndarray, dt: float, cutoff: float) -> np.ndarray:
    """Bin index per sample: torque quantile bin, plus :data:`BINS` when it falls.

    ``torque``: the filtered measured (or current-derived) transmitted torque, N m, of the
    compared samples. Samples of bins with less than :data:`MIN_SHARE` of them get -1.
    """
    tau = np.asarray(torque, dtype=float)
    rising = np.gradient(R.lowpass(tau, dt, cutoff), dt) >= 0.0
    out = np.full(tau.size, -1, dtype=int)
    for k, sel in enumerate((rising, ~rising)):
        if sel.sum() < BINS:
            continue
        edges = np.quantile(tau[sel], np.linspace(0.0, 1.0, BINS + 1))
        idx = np.clip(np.searchsorted(edges, tau[sel], side="right") - 1, 0, BINS - 1)
        out[sel] = idx + k * BINS
    counts = np.bincount(out[out >= 0], minlength=2 * BINS)
    small = counts < MIN_SHARE * tau.size
    out[(out >= 0) & small[np.maximum(out, 0)]] = -1
    return out


def project(r: np.ndarray, bins: np.ndarray) -> np.ndarray:
    """``r`` replaced by its mean over each bin (0 outside the bins)."""
    ok = bins >= 0
    n = int(bins.max()) + 1 if ok.any() else 0
    out = np.zeros_like(r, dtype=float)
    if not n:
        return out
    counts = np.bincount(bins[ok], minlength=n)
    sums = np.bincount(bins[ok], weights=r[ok], minlength=n)
    means = np.divide(sums, counts, out=np.zeros(n), where=counts > 0)
    out[ok] = means[bins[ok]]
    return out


def spring_noise(noise: dict[str, float], bins: np.ndarray, dt: float,
                 cutoff: float) -> dict[str, float]:
    """The channels' noise NMSE after :func:`project`: a bin mean keeps the noise of
    ``n_bins / N_independent`` of the samples (filtered noise is correlated over
    ``1 / (2 cutoff dt)`` samples)."""
    used = int(np.unique(bins[bins >= 0]).size)
    independent = max(1.0, bins.size * min(1.0, 2.0 * cutoff * dt))
    share = min(1.0, used / independent)
    out = {k: v * share for k, v in noise.items() if k != "mean"}
    out["mean"] = float(np.mean(list(out.values()))) if out else 0.0
    return out
