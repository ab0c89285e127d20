"""The measurement noise of a record's comparison channels, estimated from the record alone.

Two kinds of noise reach the filtered channels (:func:`.residuals.channels`):

* white noise added to a measured signal (current, torque sensor): its standard deviation
  is read from the raw signal twice, and the lower reading kept (:func:`white_sigma`): from
  the median absolute deviation of its third differences (a smooth signal sampled fast has
  third differences far below the noise, and a step spoils only the few that straddle it)
  and from the floor of its spectrum in the top half of the band (white noise is flat up
  to the Nyquist frequency; a joint's ringing at its slips, which the differences read as
  noise, is not). The filtered channel keeps the share :func:`white_gain` of it (the
  filter's own impulse response, not an ideal band);
* encoder quantization of the angles (motor speed is the gradient of the quantized motor
  angle): not white at all (a slowly turning encoder gives a staircase whose steps the
  filter passes as speed ripple; a fast one a uniform white-ish error). With the encoder's
  counts known, the quantization is replayed on the record's own smooth angle (the filtered
  measured angle, half a count up, as flooring counts takes half a count off on average) and
  its error pushed through the channel's own pipeline (:func:`quantization_noise`).
  Without the counts the angle's white-noise estimate stands in.

The first-difference estimate this replaces (``var(diff)/2`` of the raw channel, times the
kept share of the band) read the signal's own steps and slopes as noise and treated the
gradient of a quantized angle as white: 10-1000 x the sensor noise on speed, current and
torque. The same estimate picks which current and torque channels a record is compared on
(:func:`pick_channels`, :func:`snr_ok`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping

import numpy as np
from scipy import signal

from . import residuals as R

MAD_SCALE = 1.4826
"""Standard deviation of a normal variable per median absolute deviation."""
D3_VAR = 20.0
"""Variance of the third difference of unit white noise (1 + 9 + 9 + 1)."""
SEGMENT = 64
"""Samples per segment of :func:`spectral_sigma`'s spectrum (short, so that the few segments
a step or a breakaway spoils stay a minority for the median)."""
BANDS = 2
"""Bands the top half of the spectrum is split into; the quietest one's median level is the
noise floor (:func:`spectral_sigma`)."""
FAST = 0.5
"""Counts per sample above which the quantization error of an angle counts as white
(:func:`quantization`)."""


def white_sigma(x: np.ndarray) -> float:
    """Standard deviation of the white noise on ``x`` (its units): the lower of two estimates,
    :func:`difference_sigma` and :func:`spectral_sigma`.

    Both read white noise alone alike (within a few per cent); what the signal adds raises
    each in its own way and never lowers it: the third differences read ringing far above
    the channel filter's band as noise, the spectrum's floor reads the steps in the
    segments that hold them (the 12 steps of the unit test's 6 s current raise it by up to
    7 %, the third differences by up to 2 %). A stick-slip joint's torque rings at each slip:
    hold-out wave-drive-50 / stiction / random:0.283:4, seed 302, read 6.7 x the torque
    sensor's true noise by the third differences, 1.7 x by the spectrum's floor;
    tuttle-joint2 / amplifier_saturation / step:6.87, seed 290, 10 x against 1.3 x; over
    the 73 current and torque channels of the cases of seeds 290 and 302 the spectrum's
    floor read 0.96-1.67 x, the third differences 0.97-10 x (12 of the 73 above 1.2 x,
    against 2).
    """
    return min(difference_sigma(x), spectral_sigma(x))


def difference_sigma(x: np.ndarray) -> float:
    """White-noise standard deviation from the median absolute deviation of ``x``'s third
    differences: immune to a smooth signal (whose third differences vanish at a fast sample
    rate) and to isolated steps (each spoils four differences, which the median ignores),
    not to ringing near the Nyquist frequency."""
    x = np.asarray(x, dtype=float)
    if x.size < 8:
        return 0.0
    d = np.diff(x, 3)
    mad = float(np.median(np.abs(d - np.median(d))))
    return MAD_SCALE * mad / math.sqrt(D3_VAR)


def spectral_sigma(x: np.ndarray) -> float:
    """White-noise standard deviation from the floor of ``x``'s spectrum.

    Welch's estimate of the power spectral density over segments of :data:`SEGMENT` samples
    (linear trend removed, Hann window), the segments combined by their median (bias
    corrected); the noise density is the median level of the quietest of :data:`BANDS`
    bands above a quarter of the sample rate (white noise is flat up to the Nyquist
    frequency, the joint's motion falls off), and white noise of variance ``sigma^2`` has
    the one-sided density ``2 sigma^2`` per unit of sample rate.
    """
    x = np.asarray(x, dtype=float)
    if x.size < 8:
        return 0.0
    f, pxx = signal.welch(x, fs=1.0, nperseg=min(SEGMENT, x.size), average="median",
                          detrend="linear")
    top = pxx[f >= 0.25]
    density = min(float(np.median(b)) for b in np.array_split(top, min(BANDS, top.size)))
    return math.sqrt(0.5 * density)


@functools.lru_cache(maxsize=64)
def white_gain(dt: float, cutoff: float, derivative: bool = False) -> float:
    """Variance of a filtered channel per unit variance of white noise on its raw signal.

    The channel pipeline (``np.gradient`` over ``dt`` when ``derivative``, then
    :func:`.residuals.lowpass`) applied to a unit impulse; the sum of squares of that
    response is the gain (1/s^2 for a derivative).
    """
    n = 4096
    x = np.zeros(n)
    x[n // 2] = 1.0
    if derivative:
        x = np.gradient(x, dt)
    y = R.lowpass(x, dt, cutoff)
    return float(np.sum(y**2))


def slow_angle_estimate(angle: np.ndarray, counts: float) -> np.ndarray:
    """The angle behind a slowly turning floored encoder reading, to a fraction of a count.

    Where the reading changes, the angle crossed the boundary between the two counts (the
    higher of the two readings) half a sample before; between those crossings it is
    interpolated linearly (between two crossings of the same boundary, a turn-back or a rest
    inside the count, it is put in the middle of the count) and kept inside the count the
    reading shows, so the estimate floors to the reading again (rad). Meant for samples
    that turn less than a count (:func:`quantization`).
    """
    a = np.asarray(angle, dtype=float)
    q = 2.0 * math.pi / counts
    k = np.flatnonzero(np.diff(a) != 0.0) + 1
    if k.size == 0:
        return a + 0.5 * q
    t = np.concatenate(([0.0], k - 0.5, [a.size - 1.0]))
    v = np.concatenate(([a[0] + 0.5 * q], np.maximum(a[k], a[k - 1]), [a[-1] + 0.5 * q]))
    s = np.arange(a.size, dtype=float)
    r = np.interp(s, t, v)
    # between two crossings of the same boundary (a turn-back or a rest inside the count)
    # where in the count it went is unknown: its middle
    same = np.append(v[1:] == v[:-1], False)[np.clip(np.searchsorted(t, s, side="right") - 1,
                                                      0, t.size - 1)]
    r = np.where(same, a + 0.5 * q, r)
    return np.clip(r, a, a + q * (1.0 - 1e-9))


def quantization(angle: np.ndarray, counts: float, dt: float,
                 cutoff: float) -> tuple[np.ndarray, float]:
    """The quantization error of a floored angle reading, in two parts.

    Returns ``(slow error, fast share)``: on samples where the filtered reading turns less
    than :data:`FAST` counts per sample the error is a staircase the filter passes, read as
    the reading minus :func:`slow_angle_estimate` (its mean over them removed: flooring
    takes half a count off on average, and a model whose angles are floored the same way
    shows that offset too), rad, zero elsewhere; on the ``fast share`` of the samples it is
    white, uniform over a count (variance ``q^2/12``).
    """
    a = np.asarray(angle, dtype=float)
    q = 2.0 * math.pi / counts
    fast = np.abs(np.gradient(R.lowpass(a, dt, cutoff))) > FAST * q
    e = np.where(fast, 0.0, a - slow_angle_estimate(a, counts))
    if not fast.all():
        e[~fast] -= float(np.mean(e[~fast]))
    return e, float(np.mean(fast))


def _angle_noise(parts: list[tuple[np.ndarray, float | None, float]], dt: float, cutoff: float,
                 derivative: bool) -> float:
    """Variance of the filtered noise of a sum of quantized angles ``weight x angle``.

    ``parts``: ``(angle reading, counts per revolution, weight)``; without counts the
    angle's white noise (:func:`white_sigma`) stands in.
    """
    slow = np.zeros(parts[0][0].size)
    white = 0.0
    for angle, counts, w in parts:
        if not counts:
            white += (w * white_sigma(angle)) ** 2
            continue
        e, share = quantization(angle, counts, dt, cutoff)
        slow += w * e
        white += share * (w * 2.0 * math.pi / counts) ** 2 / 12.0
    var = white * white_gain(dt, cutoff, derivative)
    if slow.any():
        var += float(np.var(R.lowpass(np.gradient(slow, dt) if derivative else slow, dt, cutoff)))
    return var


def _channel_noise(name: str, raw: R.Raw, ratio: float, dt: float, cutoff: float,
                   counts: tuple[float | None, float | None]) -> float:
    """Variance of the measurement noise on one filtered channel (its units squared)."""
    if name in ("output_torque", "motor_current"):
        x = raw.output_torque if name == "output_torque" else raw.motor_current
        return white_sigma(x) ** 2 * white_gain(dt, cutoff)
    motor = (np.asarray(raw.motor_angle, dtype=float), counts[0], 1.0)
    if name == "transmission_error":
        out = (np.asarray(raw.output_angle, dtype=float), counts[1], 1.0)
        return _angle_noise([out, (motor[0], motor[1], -1.0 / ratio)], dt, cutoff, False)
    return _angle_noise([motor], dt, cutoff, name == "motor_speed")


def noise_nmse(raw: R.Raw, names: tuple[str, ...], ratio: float, dt: float, cutoff: float,
               measured: Mapping[str, np.ndarray],
               counts: tuple[float | None, float | None] = (None, None)) -> dict[str, float]:
    """Measurement-noise level of each filtered channel, NMSE percent, and ``"mean"``.

    The noise variance of each filtered channel (white noise on current and torque; encoder
    quantization on the angle channels, replayed with ``counts`` = (motor, output) counts
    per revolution when given) divided by the variance of the filtered measured channel
    ``measured[name]``: what the sensors alone put between a perfect model and this record.
    """
    out = {name: 100.0 * _channel_noise(name, raw, ratio, dt, cutoff, counts)
           / max(float(np.var(measured[name])), 1e-300) for name in names}
    out["mean"] = float(np.mean([out[k] for k in names])) if names else 0.0
    return out


SNR = 5.0
"""A current or torque channel is compared when its filtered signal's RMS stands this many
times above its filtered white noise's (:func:`snr_ok`)."""


def snr_ok(x: np.ndarray, dt: float, cutoff: float, ratio: float = SNR) -> bool:
    """Whether the filtered signal ``x`` stands ``ratio`` times (RMS) above its filtered white
    noise: the noise's standard deviation read by :func:`white_sigma`,
    its filtered share by the channel filter's own gain (:func:`white_gain`)."""
    noise = white_sigma(x) ** 2 * white_gain(dt, cutoff)
    return float(np.var(R.lowpass(np.asarray(x, dtype=float), dt, cutoff))) > ratio**2 * noise


def pick_channels(raw: R.Raw, locked: bool, ratio: float, dt: float, cutoff: float,
                  motor_counts: float | None, output_counts: float | None,
                  inverse: bool = False) -> tuple[str, ...]:
    """Which channels a record supports and shows above its noise: the motor angle (locked
    output) or speed when the motor encoder changes its count at all (else only when no
    other channel is left), the transmission error when it spans more than 3 output encoder
    counts (standard deviation), the torque and current when they pass :func:`snr_ok`; an
    inverse comparison: the current alone."""
    if inverse:
        return ("motor_current",)
    motion = "motor_angle" if locked else "motor_speed"
    # a motor encoder that never changes its count shows no motion: a channel with no
    # variance has no NMSE scale (a model creeping one count would read 10^300 %)
    names = [motion] if np.ptp(raw.motor_angle) > 0 else []
    if not locked and raw.output_angle is not None:
        te = R.lowpass(raw.output_angle - raw.motor_angle / ratio, dt, cutoff)
        q = 2 * math.pi / output_counts if output_counts else 0.0
        if np.std(te) > 3.0 * q:
            names.append("transmission_error")
    for name, x in (("output_torque", raw.output_torque), ("motor_current", raw.motor_current)):
        if x is not None and snr_ok(x, dt, cutoff):
            names.append(name)
    return tuple(names) or (motion,)
