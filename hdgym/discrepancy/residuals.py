"""Compare and localize: comparison channels, NMSE, effect signatures, where residuals sit.

Every comparison channel goes through the same zero-phase low-pass filter
(:func:`lowpass`), in the measurement, in the simulation and in every
signature regressor, so encoder quantization (a white-ish staircase) does
not bury the effect and no phase lag is introduced between residual and
regressor.

Channels (present when the record has what they need):

``motor_speed``
    derivative of the motor (WG) angle, rad/s (free-output records);
``motor_angle``
    motor angle, rad (locked-output records: it is ratio x torsion);
``transmission_error``
    ``output_angle - motor_angle/ratio``, output rad (kinematic error plus
    wind-up; kept only when it is more than a few encoder counts);
``output_torque``
    torque sensor, N m;
``motor_current``
    measured current, A.

NMSE follows seed 002: ``NMSE% = 100/(n sigma^2) sum (y_hat - y)^2`` with
sigma the standard deviation of the measured channel.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
from scipy import signal as sps

CHANNEL_UNITS = {"motor_speed": "rad/s", "motor_angle": "rad", "transmission_error": "rad",
                 "output_torque": "N m", "motor_current": "A"}


def default_cutoff(dt: float) -> float:
    """Filter cutoff, Hz: a twentieth of the sample rate (50 Hz at 1 kHz)."""
    return 0.05 / dt


@functools.lru_cache(maxsize=64)
def _sos(wn: float) -> np.ndarray:
    return sps.butter(2, wn, output="sos")


def lowpass(x: np.ndarray, dt: float, cutoff: float) -> np.ndarray:
    """Zero-phase 2nd-order Butterworth low-pass (applied forwards and backwards)."""
    sos = _sos(round(min(cutoff * 2.0 * dt, 0.95), 12))
    x = np.asarray(x, dtype=float)
    if x.ndim == 1 and x.size < 16:
        return x.copy()
    return sps.sosfiltfilt(sos, x, axis=0)


def quantize(angle: np.ndarray, counts: float | None) -> np.ndarray:
    """Floor an angle to whole encoder counts (as :func:`hdgym.hardware.quantize`)."""
    if not counts:
        return angle
    step = 2.0 * math.pi / counts
    return np.floor(angle / step) * step


def mean_reading(angle: np.ndarray, counts: float | None) -> np.ndarray:
    """The mean of :func:`quantize` over a count's worth of angle: ``angle`` less half a count.

    A continuous stand-in for the floored reading, so a model's prediction moves smoothly
    with its parameters (:attr:`.problem.Problem.quantized`)."""
    if not counts:
        return angle
    return angle - math.pi / counts


def nmse(y_hat: np.ndarray, y: np.ndarray) -> float:
    """Seed-002 NMSE in percent: ``100/(n var(y)) sum (y_hat - y)^2``."""
    y = np.asarray(y, dtype=float)
    var = float(np.var(y))
    if var <= 0:
        return 0.0 if np.allclose(y_hat, y) else float("inf")
    return 100.0 * float(np.mean((np.asarray(y_hat) - y) ** 2)) / var


@dataclass
class Raw:
    """Unfiltered angles, currents and torques of one run (measured or simulated)."""

    motor_angle: np.ndarray
    output_angle: np.ndarray | None = None
    output_torque: np.ndarray | None = None
    motor_current: np.ndarray | None = None


def channels(raw: Raw, names: tuple[str, ...], ratio: float, dt: float,
             cutoff: float) -> dict[str, np.ndarray]:
    """The filtered comparison channels ``names`` of one run (one filter call for all)."""
    cols = []
    for name in names:
        if name == "motor_speed":
            cols.append(np.gradient(raw.motor_angle, dt))
        elif name == "motor_angle":
            cols.append(raw.motor_angle)
        elif name == "transmission_error":
            cols.append(raw.output_angle - raw.motor_angle / ratio)
        elif name == "output_torque":
            cols.append(raw.output_torque)
        elif name == "motor_current":
            cols.append(raw.motor_current)
        else:
            raise ValueError(f"unknown channel {name!r}")
    filt = lowpass(np.column_stack(cols), dt, cutoff)
    return {name: np.ascontiguousarray(filt[:, k]) for k, name in enumerate(names)}


# ------------------------------------------------------------------ context


@dataclass
class Held:
    """What one friction side holds while it sticks (for the breakaway signature).

    Attributes:
        torque: unfiltered torque the side's friction must hold, N m in the side's
            frame (unfiltered, so the zero-phase filter cannot smear the motion that
            ends a pause into it) (``output``: transmitted torque minus load, output-referred;
            ``input``: motor torque minus transmitted torque / ratio, motor-referred;
            ``lumped``, without a torque sensor: motor torque x ratio minus load).
        speed: the side's speed, rad/s (filtered).
        stuck: samples inside a pause of the side's encoder (no count for
            :data:`hdgym.discrepancy.fitting.REST_PAUSE` or longer).
    """

    torque: np.ndarray
    speed: np.ndarray
    stuck: np.ndarray


MIN_MOVING = 50
"""Least number of moving samples for a running-friction level."""


def friction_levels(h: Held, dt: float, cutoff: float) -> tuple[float, float] | None:
    """``(static, running)`` friction levels of one side, read from the record alone.

    *static* is the largest torque the side held while stuck (a lower bound of its
    breakaway torque: had the torque exceeded it, the side would have moved);
    *running* is the sign-of-velocity term of a least-squares fit of the (filtered)
    torque to ``F sgn(w) + b w + J dw/dt`` over the samples where the side moves
    (faster than 20 % of its 90th-percentile speed). None without a pause or motion.
    """
    if not h.stuck.any():
        return None
    w = h.speed
    moving = np.abs(w) > 0.2 * float(np.quantile(np.abs(w), 0.9))
    if int(moving.sum()) < MIN_MOVING:
        return None
    X = np.column_stack([np.sign(w), w, np.gradient(w, dt)])[moving]
    beta, *_ = np.linalg.lstsq(X, lowpass(h.torque, dt, cutoff)[moving], rcond=None)
    static = float(np.max(np.abs(h.torque[h.stuck])))
    return static, max(float(beta[0]), 0.0)


@dataclass
class Context:
    """Measured quantities the signatures and the localization use (all filtered).

    Attributes:
        time: s.
        theta_m: motor (WG) angle, rad.
        speed: motor speed, rad/s.
        torsion: output rad (motor/ratio - output; locked: motor/ratio), or None.
        torque: transmitted torque, N m (sensor, else K_t ratio x current), or None.
        current: measured (else commanded) current, A.
        dt, cutoff: sample period (s) and filter cutoff (Hz).
        held: per friction side (``output``, ``input`` or ``lumped``), the torque it
            holds while stuck (:class:`Held`); empty when the record has no pause.
    """

    time: np.ndarray
    theta_m: np.ndarray
    speed: np.ndarray
    torsion: np.ndarray | None
    torque: np.ndarray | None
    current: np.ndarray
    dt: float
    cutoff: float
    held: dict[str, Held] = field(default_factory=dict)


def _lstsq_explained(y: np.ndarray, X: np.ndarray) -> tuple[float, np.ndarray]:
    """Fraction of ``|y|^2`` explained by least squares on the columns of ``X``."""
    if X.size == 0 or not np.any(y):
        return 0.0, np.zeros(X.shape[1] if X.ndim == 2 else 0)
    X = X - X.mean(axis=0)
    scale = np.linalg.norm(X, axis=0)
    ok = scale > 1e-300
    if not ok.any():
        return 0.0, np.zeros(X.shape[1])
    beta = np.zeros(X.shape[1])
    b, *_ = np.linalg.lstsq(X[:, ok] / scale[ok], y - y.mean(), rcond=None)
    beta[ok] = b / scale[ok]
    fit = X @ beta
    return float(max(0.0, 1.0 - np.sum((y - y.mean() - fit) ** 2) / np.sum(y**2))), beta


def _play(x: np.ndarray, r: float) -> np.ndarray:
    """Play (backlash) operator of width ``2 r``: the memory a Maxwell-slip element keeps."""
    out = np.empty_like(x)
    y = x[0]
    for k, v in enumerate(x):
        if v - y > r:
            y = v - r
        elif y - v > r:
            y = v + r
        out[k] = y
    return out


def _regressors(kind: str, c: Context) -> np.ndarray:
    """Unfiltered signature regressors (columns) of ``kind``."""
    w = c.speed
    ws = max(float(np.std(w)), 1e-12)
    sgn = np.tanh(w / (0.02 * ws))
    if kind in ("order_lines_te", "order_lines_speed"):
        # a friction ripple opposes the motion: its lines flip sign with the direction
        flip = sgn if kind == "order_lines_speed" else 1.0
        cols = []
        for n in (1, 2, 3, 4, 6, 8):
            cols += [flip * np.sin(n * c.theta_m), flip * np.cos(n * c.theta_m)]
        return np.column_stack(cols)
    if kind == "sign_steps":
        return sgn[:, None]
    if kind == "speed_bins":
        return np.column_stack([w, w * np.abs(w) / ws])
    if kind == "speed_bins_low":
        return np.column_stack([sgn * np.exp(-(w / (f * ws)) ** 2) for f in (0.02, 0.1, 0.3)])
    if kind == "breakaway":
        # the torque held while stuck beyond the running friction: a model without a
        # static level slips there (its torque stays near the running level, so the
        # torque residual is minus this) and breaks away early (speed residual)
        cols = []
        for h in c.held.values():
            lv = friction_levels(h, c.dt, c.cutoff)
            if lv is None or lv[0] <= lv[1]:
                continue
            excess = np.where(h.stuck, np.maximum(np.abs(h.torque) - lv[1], 0.0), 0.0)
            cols.append(np.sign(h.torque) * excess)
        return np.column_stack(cols) if cols else np.zeros((w.size, 0))
    if kind == "torque_dependence":
        if c.torque is None:
            return np.zeros((w.size, 0))
        return (sgn * np.abs(c.torque))[:, None]
    if kind == "clipped_current":
        return np.column_stack([np.abs(w) * np.sign(c.current), c.current * np.abs(w) / ws])
    if kind == "cubic_torsion":
        if c.torsion is None:
            return np.zeros((w.size, 0))
        x = c.torsion / max(float(np.std(c.torsion)), 1e-300)
        return np.column_stack([x**3, np.abs(x) * x])
    if kind == "torsion_loops":
        if c.torsion is None:
            return np.zeros((w.size, 0))
        s = max(float(np.std(c.torsion)), 1e-300)
        x = c.torsion / s
        return np.column_stack([x - _play(x, r) for r in (0.05, 0.2, 0.6)])
    raise ValueError(f"unknown signature {kind!r}")


def signature(kind: str, residuals: Mapping[str, np.ndarray], weights: Mapping[str, float],
              c: Context) -> dict:
    """How much of the residual the signature ``kind`` explains.

    The regressors (e.g. sin/cos of orders of the WG angle, play operators of
    the torsion, speed functions) are filtered like the residuals, then each
    channel's residual is regressed on them (a linear model per channel, since
    an effect shows with a different gain and sign in each channel).

    Returns:
        ``{"kind", "explained"}`` (fraction of the weighted residual energy,
        0..1) plus a detail per kind (order amplitudes, loop width, ...).
    """
    X = _regressors(kind, c)
    if X.shape[1]:
        X = lowpass(X, c.dt, c.cutoff)
    total, expl = 0.0, 0.0
    best_ch, best_frac, best_beta = None, -1.0, None
    for ch, r in residuals.items():
        e = float(np.sum(r**2)) * weights[ch]
        frac, beta = _lstsq_explained(r, X)
        total += e
        expl += frac * e
        if frac * e > best_frac:
            best_ch, best_frac, best_beta = ch, frac * e, beta
    out: dict = {"kind": kind, "explained": expl / total if total > 0 else 0.0,
                 "channel": best_ch}
    if kind == "breakaway":
        for side, h in c.held.items():
            lv = friction_levels(h, c.dt, c.cutoff)
            if lv is not None:
                out[side] = {"static": lv[0], "running": lv[1],
                             "ratio": lv[0] / lv[1] if lv[1] > 0 else None}
    if kind.startswith("order_lines") and best_beta is not None and best_beta.size:
        amps = np.hypot(best_beta[0::2], best_beta[1::2])
        out["orders"] = {str(n): float(a) for n, a in zip((1, 2, 3, 4, 6, 8), amps, strict=True)}
    return out


SIGNATURES: dict[str, Callable] = {k: signature for k in (
    "order_lines_te", "order_lines_speed", "sign_steps", "speed_bins", "speed_bins_low",
    "breakaway", "torque_dependence", "clipped_current", "cubic_torsion", "torsion_loops")}


# ------------------------------------------------------------------ localize


def order_spectrum(r: np.ndarray, theta_m: np.ndarray, max_order: float = 10.0,
                   speed: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Amplitude of ``r`` at orders of the WG angle (resampled to equal angle, FFT).

    With ``speed``, each direction of rotation is analysed on its own (a
    friction ripple flips sign with the direction, so mixing both would
    cancel it) and the amplitudes are averaged, weighted by sample count.

    Returns ``(orders, amplitudes)``; empty when the WG turned less than two
    revolutions one way.
    """
    if speed is not None:
        parts = []
        for sel in (speed > 0, speed < 0):
            if sel.sum() > 64:
                o, a = order_spectrum(r[sel], theta_m[sel], max_order)
                if o.size:
                    parts.append((o, a, int(sel.sum())))
        if not parts:
            return np.zeros(0), np.zeros(0)
        o = parts[0][0]
        tot = sum(n for _, _, n in parts)
        return o, sum(np.interp(o, oo, aa) * n for oo, aa, n in parts) / tot
    th = np.asarray(theta_m, dtype=float)
    span = float(th.max() - th.min())
    if span < 4 * math.pi:
        return np.zeros(0), np.zeros(0)
    # monotone part only: sort by angle and average repeats (constant-speed runs)
    order = np.argsort(th, kind="stable")
    th_s, r_s = th[order], r[order]
    n = int(min(2 ** math.ceil(math.log2(max(len(th), 64))), 1 << 16))
    grid = np.linspace(th_s[0], th_s[-1], n, endpoint=False)
    rg = np.interp(grid, th_s, r_s)
    rg = rg - rg.mean()
    amp = 2.0 * np.abs(np.fft.rfft(rg * np.hanning(n))) / (0.5 * n)
    orders = np.fft.rfftfreq(n, d=(grid[1] - grid[0])) * 2 * math.pi
    keep = orders <= max_order
    return orders[keep], amp[keep]


def _spans(t: np.ndarray, e: np.ndarray, nwin: int = 40) -> list[dict]:
    edges = np.linspace(0, t.size, nwin + 1).astype(int)
    energy = np.array([np.mean(e[a:b]) if b > a else 0.0 for a, b in zip(edges[:-1], edges[1:],
                                                                           strict=True)])
    thr = 2.0 * max(float(np.median(energy)), 1e-300)
    hot = energy > thr
    spans, k = [], 0
    tot = float(energy.sum()) or 1.0
    while k < nwin:
        if hot[k]:
            j = k
            while j + 1 < nwin and hot[j + 1]:
                j += 1
            spans.append({"t0": float(t[edges[k]]), "t1": float(t[min(edges[j + 1], t.size - 1)]),
                          "share": float(energy[k:j + 1].sum() / tot)})
            k = j + 1
        else:
            k += 1
    spans.sort(key=lambda s: -s["share"])
    return spans[:5]


def _bands(x: np.ndarray, e: np.ndarray, nb: int = 6) -> list[dict]:
    ax = np.abs(x)
    qs = np.unique(np.quantile(ax, np.linspace(0, 1, nb + 1)))
    if qs.size < 2:
        return []
    out = []
    tot = float(e.sum()) or 1.0
    for a, b in zip(qs[:-1], qs[1:], strict=True):
        m = (ax >= a) & (ax <= b)
        if m.any():
            out.append({"lo": float(a), "hi": float(b), "rms": float(math.sqrt(np.mean(e[m]))),
                        "share": float(e[m].sum() / tot)})
    return out


def localize(residuals: Mapping[str, np.ndarray], weights: Mapping[str, float],
             c: Context) -> dict:
    """Where the (weighted) residual energy concentrates.

    Returns ``{"time_spans", "speed_bands", "orders", "torsion_regions", "channels"}``:
    time spans (s) holding more than twice the median energy, residual RMS per
    band of |motor speed| (rad/s), the strongest orders of the WG angle in
    the residual (per channel), and residual RMS per band of |torsion|.
    """
    e = sum(weights[ch] * r**2 for ch, r in residuals.items())
    out: dict = {"time_spans": _spans(c.time, e)}
    out["speed_bands"] = _bands(c.speed, e)
    out["torsion_regions"] = _bands(c.torsion, e) if c.torsion is not None else []
    orders = []
    for ch, r in residuals.items():
        o, a = order_spectrum(r, c.theta_m, speed=c.speed)
        if o.size:
            sel = (o > 0.5)
            o, a = o[sel], a[sel]
            picked: list[float] = []
            for k in np.argsort(a)[::-1]:
                if len(picked) == 3:
                    break
                if any(abs(o[k] - q) < 0.3 for q in picked):  # same line, next bin
                    continue
                picked.append(float(o[k]))
                orders.append({"channel": ch, "order": round(float(o[k]), 2),
                               "amplitude": float(a[k]), "unit": CHANNEL_UNITS[ch]})
    out["orders"] = orders
    tot = float(sum(weights[ch] * np.sum(r**2) for ch, r in residuals.items())) or 1.0
    out["channels"] = {ch: float(weights[ch] * np.sum(r**2) / tot) for ch, r in residuals.items()}
    return out
