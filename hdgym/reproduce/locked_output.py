"""Locked-output experiments of Seyfferth & Angeles (1995), as plain functions.

The report verifies its model with the output shaft locked: a sinusoidal motor
current and the largest input rotation per ampere ("transfer function", figs 18
and 21, fitted by eq. 14 near resonance), and a current step from rest (fig. 22).
:mod:`hdgym.reproduce.seyfferth` turns these into the fidelity items; the tests
call them directly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from hdgym.effects import flags_of
from hdgym.params import JointParams
from hdgym.physics import layout as L
from hdgym.reproduce.common import simulator


def gain_curve(p: JointParams, amplitude: float, freqs: np.ndarray, cycles: int = 8,
               settle: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """Locked output, sine current: largest input rotation per ampere at each frequency.

    Each frequency starts from rest and runs ``max(cycles / f, settle)`` s;
    the gain is half the peak-to-peak motor angle over the last two cycles
    divided by ``amplitude`` (Seyfferth's "transfer function", rad/A).

    Returns:
        ``(gain, stuck)``: gain (rad/A) and the fraction of those last two
        cycles the motor spent stuck (speed exactly zero) per frequency.
    """
    sim = simulator(p, locked_output=True, sensors=False)
    gains, stuck = [], []
    for f in np.asarray(freqs, dtype=float):
        if not (f > 0 and amplitude > 0):
            raise ValueError(f"gain_curve: frequency and amplitude must be > 0, got {f}, "
                             f"{amplitude}")
        t, _, _, st = sim.trajectory(f"sine:{float(amplitude)!r}:{float(f)!r}",
                                     max(cycles / f, settle))
        last = t >= t[-1] - 2.0 / f
        th = st[last, L.TH_M]
        gains.append(0.5 * float(np.ptp(th)) / amplitude)
        stuck.append(float(np.mean(st[last, L.W_M] == 0.0)))
    return np.array(gains), np.array(stuck)


@dataclass(frozen=True)
class SecondOrder:
    """Eq. 14 fitted to a transfer function: ``|H| = (K_t/J_1) / |omega_n^2 - w^2 + 2 j zeta
    omega_n w|`` over the points at or above ``frac`` of the peak."""

    zeta: float
    omega_n: float
    kt_over_j: float

    def gain(self, f: np.ndarray) -> np.ndarray:
        """Transfer function of the fitted system at ``f`` Hz, rad/A."""
        w = 2 * np.pi * np.asarray(f, dtype=float)
        return self.kt_over_j / np.hypot(self.omega_n**2 - w**2, 2 * self.zeta * self.omega_n * w)


def fit_second_order(freqs: np.ndarray, gain: np.ndarray, kt_over_j: float,
                     frac: float = 0.5) -> SecondOrder:
    """Least-squares fit of eq. 14's (zeta, omega_n) to the resonance region of a gain curve.

    ``K_t/J_1`` is fixed (eq. 14 normalizes by the input inertia), so the
    fit has the same two unknowns as the paper's; the resonance region is
    every point whose gain is at least ``frac`` of the peak.
    """
    f = np.asarray(freqs, dtype=float)
    g = np.asarray(gain, dtype=float)
    sel = g >= frac * g.max()
    if sel.sum() < 3:
        raise ValueError("fit_second_order: fewer than 3 points in the resonance region")
    w = 2 * np.pi * f[sel]

    def resid(z: np.ndarray) -> np.ndarray:
        return kt_over_j / np.hypot(z[1] ** 2 - w**2, 2 * z[0] * z[1] * w) - g[sel]

    sol = least_squares(resid, [0.3, 2 * np.pi * f[np.argmax(g)]], bounds=([1e-3, 0.1], [3.0, 1e3]))
    return SecondOrder(float(sol.x[0]), float(sol.x[1]), kt_over_j)


#: fig. 22: the step current (A) and the top of the paper's input-angle axis (rad)
STEP_CURRENT = 1.1
STEP_MAX_ANGLE = 0.6
#: start angles of the step across one period of the kinematic error (pi rad of WG angle)
STEP_ANGLES = 16


def step_from_rest(p: JointParams, angles: int = STEP_ANGLES, current: float = STEP_CURRENT,
                   duration: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Locked output, a current step from rest at ``angles`` WG angles spread over pi rad.

    The joint starts relaxed (no torque, hysteresis on its virgin branch) at each
    angle; the kinematic error's phase at the start is what the angle changes.

    Returns:
        ``(start, rise, final)``: the start angles (rad), the largest rise of the
        input angle over the step (rad) and its rise at the end (rad), per angle.
    """
    sim = simulator(p, locked_output=True, sensors=False)
    row = L.pack(p)[None, :]
    flags = flags_of(p.effects, True)
    start = np.arange(angles) * math.pi / angles
    rise, final = [], []
    n = int(round(duration / sim.ctrl_dt))
    for a in start:
        x0 = L.initial_state(row, flags, float(a), None)[0]
        _, _, _, st = sim.trajectory(np.full(n, current), state=x0)
        th = st[:, L.TH_M] - a
        rise.append(float(th.max()))
        final.append(float(th[-1]))
    return start, np.array(rise), np.array(final)


def step_after_cycle(sim: Any, sign: float) -> float:
    """Largest rise of the input angle in a 1.1 A step taken after one slow current cycle."""
    t = np.arange(2000) * sim.ctrl_dt
    pre = np.where(t < 2.0, sign * 1.1 * np.sin(np.pi * t), 0.0)
    _, _, _, st = sim.trajectory(np.concatenate([pre, np.zeros(1000)]))
    _, _, _, st2 = sim.trajectory(np.full(1000, 1.1), state=st[-1])
    return float(np.max(st2[:, L.TH_M]) - st[-1, L.TH_M])


def first_stuck_turn(p: JointParams, sim: Any, f: float,
                     cycles: int = 8) -> tuple[float, float, float] | None:
    """Where a locked-output 1 A sine first sticks over its last two cycles.

    Returns ``(|tau_m - T_k/N|, B_m0(L), deceleration)`` at the first control period
    with the shaft stopped (N m, N m, rad/s² over the period before), or None.
    """
    t, _, _, st = sim.trajectory(f"sine:1.0:{f!r}", cycles / f)
    w = st[:, L.W_M]
    idx = np.flatnonzero((t >= t[-1] - 2.0 / f) & (w == 0.0))
    if idx.size == 0 or idx[0] == 0:
        return None
    k = int(idx[0])
    net = p.motor.torque_constant * st[k, L.CUR] - st[k, L.TK] / p.ratio
    b_m0 = p.friction.input.coulomb + p.hysteresis.startup_slope * st[k, L.HZ + 4]
    return abs(float(net)), float(b_m0), abs(float(w[k - 1])) / sim.ctrl_dt


def no_stop_bound(p: JointParams, f: float, b_m0: float | None = None) -> tuple[float, float]:
    """What a locked-output sine needs to turn at ``f`` Hz without a stop (eq. 7).

    Just before a turn the shaft decelerates under ``tau_m - T_k/N - B_m0``; it turns
    without sticking only if ``|tau_m - T_k/N| > B_m0`` there, so the deceleration must
    reach ``2 B_m0 / J1`` (``b_m0``, N m; default the startup torque with no load history,
    the smallest it gets). A sinusoidal response of amplitude ``A`` decelerates at
    ``A (2 pi f)^2`` at its turns.

    Returns:
        ``(deceleration, amplitude)``: ``2 B_m0 / J1`` (rad/s²) and the sinusoid's
        amplitude (rad) that reaches it at ``f``.
    """
    decel = 2.0 * (p.friction.input.coulomb if b_m0 is None else b_m0) / p.motor.inertia
    return decel, decel / (2.0 * math.pi * f) ** 2
