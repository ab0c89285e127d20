"""Order-domain comparison: line amplitudes against each run's own WG angle.

A kinematic error or a friction ripple is a line at an order of the WG angle. Compared in
time, its trace must sit at the same instant in the model as in the record, and above the
comparison filter's cutoff (a WG that turns faster than the cutoff over the order, e.g.
90 Hz at order 2 on a drive at 285 rad/s and 1 kHz) the time channels do not show it at
all. Compared as *lines* it cannot slip: what the filter removes from each run's raw
channel (the channel minus its low-passed self) is regressed, window by window, on sines
and cosines of orders of that run's own WG angle, and the coefficients of model and record
are compared (:class:`Lines`, the ``"lines"`` comparison of :class:`.problem.Problem`).

Two line channels (:data:`LINE_CHANNELS`):

``te_lines``
    the transmission error (``output - motor/ratio``, output rad) at orders
    :data:`ORDERS` of the WG angle: kinematic error, and the torsion a friction ripple
    causes;
``speed_lines``
    the motor speed (rad/s) at the same orders, times the sign of the motion (a friction
    ripple opposes the motion).

Windows (:func:`windows`) span :data:`WINDOW_TURNS` WG turns of measured travel, so split
lines and slow changes of speed show as coefficients that change from window to window.

The model runs window by window without ever being put onto the measured state: at each
window's end only its slow drift is removed (:func:`.restarts.drift`: the measured minus the
model's motor angle over the window's last half, fitted by a straight line, whose value
and slope shift the model's motor angle and speed; the torsion and its rate stay the
model's own). Multiple-shooting restarts from the filtered measured state (the time
channels') put the filter's errors into the state (a motor-speed line above the cutoff
is missing from the filtered speed), and the model rings from there: the (unfiltered)
line channels of the exact model were then 30 % NMSE off on the hold-out record hduc20 /
position_dependent_friction / sine:2.75:2 and 44 % on tuttle-joint1 /
position_dependent_friction / step:2.57 (seed 14); with the drift removed instead, 0.007 %.
A whole-record free run is exact for the exact model too, but any other model drifts into
a different motion, whose lines differ for reasons that have nothing to do with lines.

A line channel is compared only where the time channels cannot show every line and the
record has lines (:func:`select`): the record's typical WG speed puts the highest line
above :data:`BAND` x the filter cutoff, the record's lines stand :data:`SNR` x above their
noise (:func:`noise_var`: the encoders' quantization, the only noise on an angle), and they
repeat from window to window (:func:`coherence`; what else the regression picks up, the
ringing and the rest of the motion, does not: on the tuned none (current steps) record,
whose joint has no lines, a base model fitted some per cent off left 4.4 % and 17.5 % NMSE
on the unfiltered line channels with nothing missing).
"""

from __future__ import annotations

import math

import numpy as np

from .residuals import lowpass

ORDERS = (1.0, 2.0, 4.0)
"""Orders of the WG angle compared (kinematic error: 2 dominant, then 4, sometimes 1; the
friction ripple's 1 and 2)."""
WINDOW_TURNS = 2.0
"""WG turns of measured travel per window."""
MIN_SAMPLES = 64
"""Least samples per window (the regression has 2 + 2 x len(ORDERS) columns)."""
MIN_WINDOWS = 2
"""Least windows for a line channel (a record of fewer turns has no order domain)."""
SNR = 5.0
"""Least ratio of the measured lines' RMS to their noise RMS for a line channel."""
BAND = 0.5
"""A line channel is compared when its highest line lies above this share of the cutoff
(the zero-phase filter keeps 94 % of a line at half its cutoff, half at the cutoff)."""
COHERENT = 3.0
"""Least :func:`coherence` of a line channel (lines that repeat by three standard errors)."""
LINE_CHANNELS = ("te_lines", "speed_lines")


def windows(theta: np.ndarray, moving: np.ndarray) -> np.ndarray:
    """``(start, stop)`` sample ranges, each :data:`WINDOW_TURNS` WG turns of moving travel.

    ``theta``: the WG (motor) angle, rad; ``moving``: samples in which it moves. Travel
    counts only while the joint moves; a window holds at least :data:`MIN_SAMPLES`
    samples. The last, incomplete stretch is dropped.
    """
    th = np.asarray(theta, dtype=float)
    step = np.abs(np.diff(th, prepend=th[0]))
    trav = np.cumsum(np.where(moving, step, 0.0))
    need = WINDOW_TURNS * 2 * math.pi
    out = []
    a, n = 0, trav.size
    while a < n:
        b = max(int(np.searchsorted(trav, trav[a] + need, side="left")), a + MIN_SAMPLES)
        if b > n:
            break
        out.append((a, b))
        a = b
    return np.asarray(out, dtype=int).reshape(-1, 2)


def lines(y: np.ndarray, theta: np.ndarray, wins: np.ndarray,
          sign: np.ndarray | None = None) -> np.ndarray:
    """Line coefficients of ``y`` per window: ``[sin, cos] x ORDERS`` of ``theta``, flattened.

    Each window's ``y`` is regressed on a constant, a linear trend and ``sign x sin(n
    theta)``, ``sign x cos(n theta)`` for each order (``sign``: +-1 per sample, the
    direction of motion; None: 1).
    """
    y = np.asarray(y, dtype=float)
    th = np.asarray(theta, dtype=float)
    out = np.empty((len(wins), 2 * len(ORDERS)))
    for k, (a, b) in enumerate(wins):
        s = 1.0 if sign is None else sign[a:b]
        cols = [np.ones(b - a), np.linspace(-0.5, 0.5, b - a)]
        for n in ORDERS:
            cols += [s * np.sin(n * th[a:b]), s * np.cos(n * th[a:b])]
        out[k] = np.linalg.lstsq(np.column_stack(cols), y[a:b], rcond=None)[0][2:]
    return out.ravel()


def channel_lines(motor_angle: np.ndarray, output_angle: np.ndarray, ratio: float, dt: float,
                  cutoff: float, wins: np.ndarray, names: tuple[str, ...]
                  ) -> dict[str, np.ndarray]:
    """The line coefficients (:func:`lines`) of ``names`` for one run's raw angles, rad, of
    what the time channels' filter (``cutoff``, Hz) removes from them."""
    th = np.asarray(motor_angle, dtype=float)
    speed = np.gradient(th, dt)
    out = {}
    for name in names:
        if name == "te_lines":
            te = np.asarray(output_angle, dtype=float) - th / ratio
            out[name] = lines(te - lowpass(te, dt, cutoff), th, wins)
        elif name == "speed_lines":
            out[name] = lines(speed - lowpass(speed, dt, cutoff), th, wins, np.sign(speed))
        else:
            raise ValueError(f"unknown line channel {name!r}")
    return out


def noise_var(name: str, counts: tuple[float, float], ratio: float, dt: float,
              samples: float) -> float:
    """Variance of one line coefficient from the encoders' quantization.

    A quantized angle carries a uniform error of one count (variance ``q^2 / 12``); the
    transmission error has both encoders' (the motor's divided by the ratio), the
    central-difference speed ``q_m^2 / (24 dt^2)``. A coefficient of a window of
    ``samples`` samples has ``2 / samples`` of the sample variance.
    """
    qm, qo = (2 * math.pi / c if c else 0.0 for c in counts)
    if name == "te_lines":
        var = ((qm / ratio) ** 2 + qo**2) / 12.0
    elif name == "speed_lines":
        var = qm**2 / (24.0 * dt * dt)
    else:
        raise ValueError(f"unknown line channel {name!r}")
    return 2.0 * var / max(samples, 1.0)


def coherence(c: np.ndarray) -> float:
    """How much a channel's lines repeat from one window to the next, in standard errors.

    ``c``: a channel's coefficients (:func:`lines`, flattened over windows). A line at an
    order of the angle keeps its amplitude and phase from window to window (a split line
    near an order turns slowly), so neighbouring windows' coefficients agree; what the
    regression picks up of anything else (ringing, the rest of the motion) does not. The
    lag-one correlation ``1 - mean |c_k - c_(k-1)|^2 / (2 mean |c_k|^2)`` is 0 for
    coefficients that do not repeat (standard error ``1 / sqrt(windows)``) and 1 for
    lines; returns it in standard errors.
    """
    w = c.reshape(-1, 2 * len(ORDERS))
    if len(w) < 2:
        return 0.0
    power = float(np.mean(np.sum(w**2, axis=1)))
    if not power > 0:
        return 0.0
    rho = 1.0 - float(np.mean(np.sum(np.diff(w, axis=0) ** 2, axis=1))) / (2.0 * power)
    return rho * math.sqrt(len(w))


def select(measured: dict[str, np.ndarray], noise: dict[str, float], typical_speed: float,
           cutoff: float) -> tuple[str, ...]:
    """Line channels worth comparing: lines the filter cuts, standing above their noise.

    ``typical_speed``: the record's 90th-percentile moving WG speed, rad/s. The highest
    line, ``max(ORDERS) x typical_speed / 2 pi`` Hz, must exceed :data:`BAND` x the cutoff
    (below it the time channels show every line); the measured coefficients' RMS must be
    :data:`SNR` x their noise RMS (``noise``: a coefficient's variance), and they must be
    lines: repeating from window to window by :data:`COHERENT` standard errors
    (:func:`coherence`).
    """
    if max(ORDERS) * typical_speed / (2 * math.pi) <= BAND * cutoff:
        return ()
    return tuple(k for k, c in measured.items() if float(np.mean(c**2)) >= SNR**2 * noise[k]
                 and coherence(c) >= COHERENT)


class Lines:
    """The line channels of one record: windows, measured coefficients and their noise.

    Args:
        motor_angle, output_angle: the record's raw angles, rad.
        ratio, dt, cutoff: the drive's ratio, the sample period (s), the time channels'
            filter cutoff (Hz).
        moving: samples in which the measured WG moves.
        counts: encoder counts per motor (WG) and per output turn.
        names: compare exactly these line channels (a validation record takes the
            training record's); None: :func:`select` chooses.
    """

    def __init__(self, motor_angle: np.ndarray, output_angle: np.ndarray, ratio: float,
                 dt: float, cutoff: float, moving: np.ndarray, counts: tuple[float, float],
                 names: tuple[str, ...] | None = None) -> None:
        self.ratio, self.dt, self.cutoff = ratio, dt, cutoff
        th = np.asarray(motor_angle, dtype=float)
        self.wins = windows(th, moving)
        enough = len(self.wins) >= MIN_WINDOWS
        wanted = (LINE_CHANNELS if names is None else names) if enough else ()
        self.measured = channel_lines(th, output_angle, ratio, dt, cutoff, self.wins, wanted)
        n = float(np.mean(np.diff(self.wins, axis=1))) if enough else 1.0
        self.noise_var = {k: noise_var(k, counts, ratio, dt, n) for k in self.measured}
        if names is None:
            speed = np.abs(np.gradient(th, dt))
            typical = float(np.quantile(speed[moving], 0.9)) if moving.any() else 0.0
            self.names = select(self.measured, self.noise_var, typical, cutoff)
        else:
            self.names = tuple(k for k in names if k in self.measured)

    def sigma2(self, name: str) -> float:
        """The measured coefficients' mean square (the channel's NMSE denominator)."""
        return max(float(np.mean(self.measured[name] ** 2)), 1e-300)

    def noise_nmse(self, name: str) -> float:
        """Measurement-noise NMSE of the channel, percent."""
        return 100.0 * self.noise_var[name] / self.sigma2(name)
