"""Baseline controllers for the resonance task, with the same interface as an SB3 policy.

* :class:`PISpeedController`: a PI speed loop on the measured motor speed,
  designed with python-control on a linear model of the joint (rigid
  two-inertia joint reflected to the motor, first-order current loop) for a
  stated crossover frequency and phase margin, with anti-windup
  (back-calculation onto the amplifier's current and back-EMF limits).
* :class:`ConstantCurrent`: a constant normalized current command (1.0 is
  the amplifier's full current).
* :class:`RippleCurrent`, :class:`DampingCurrent`: full current shaped
  against the vibration, a 2x-order ripple locked to the measured WG angle
  or active damping from the torque sensor (hand-made attempts at crossing
  the trap without more current).

Both take a batch of observations of ``HarmonicDriveResonance-v0`` and
return a batch of actions through ``predict(obs, state, episode_start,
deterministic)`` like an SB3 policy, so :mod:`agents.evaluate` runs them
exactly like a trained policy. Controllers see measurements only: the
measured motor speed and the target speed from the observation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import control
import numpy as np

from hdgym.params import JointParams

# observation channels of the resonance task (hdgym.envs.tasks.ResonanceTask.obs_names)
OBS_SPEED = 0  # measured motor speed / target speed
OBS_COS, OBS_SIN = 2, 3  # cos, sin of the measured WG angle
OBS_TARGET = 6  # target speed / speed scale
OBS_OSC = 7  # torque sensor minus its running mean / torque scale


def motor_speed_model(p: JointParams) -> control.TransferFunction:
    """Linear model: motor (WG) speed in rad/s per commanded current in A.

    The joint is taken rigid (flexspline spring and kinematic error left out)
    so the output inertia reflects to the motor through the ratio; viscous
    friction of both sides is kept, Coulomb friction is left to the integral
    action. The current loop is first order at the amplifier bandwidth::

        G(s) = K_t / (J s + b) * 1 / (s / w_a + 1)
        J = J_m + J_o / r^2,   b = b_in + b_out / r^2
    """
    r = p.ratio
    j = p.motor.inertia + p.load.inertia / r**2
    b = p.friction.input.viscous + p.friction.output.viscous / r**2
    wa = 2.0 * math.pi * p.amplifier.bandwidth
    return control.tf([p.motor.torque_constant], [j, b]) * control.tf([1.0], [1.0 / wa, 1.0])


@dataclass(frozen=True)
class PIDesign:
    """The designed gains and what python-control reports for the loop."""

    kp: float  # A per rad/s
    ki: float  # A per rad
    crossover_hz: float  # requested gain crossover, Hz
    phase_margin_deg: float  # requested phase margin, deg
    achieved_pm_deg: float  # control.margin on the designed loop
    achieved_crossover_hz: float
    gain_margin: float

    def describe(self) -> str:
        return (f"PI speed loop: kp = {self.kp:.4g} A s/rad, ki = {self.ki:.4g} A/rad "
                f"(Ti = {self.kp / self.ki * 1e3:.3g} ms); crossover "
                f"{self.achieved_crossover_hz:.3g} Hz, phase margin "
                f"{self.achieved_pm_deg:.3g} deg (requested "
                f"{self.crossover_hz:.3g} Hz, {self.phase_margin_deg:.3g} deg)")


def design_pi(p: JointParams, crossover_hz: float = 5.0,
              phase_margin_deg: float = 60.0) -> PIDesign:
    """PI gains ``C(s) = kp + ki / s`` for a gain crossover and phase margin.

    At the crossover ``w_c`` the loop ``C G`` must have unit gain and phase
    ``-180 deg + PM``: the PI zero is placed so its phase lag makes up the
    difference, then ``kp`` sets the gain. ``control.margin`` checks the
    result. The crossover is kept well below the torsional resonance (tens
    of Hz) so the rigid model holds there.
    """
    g = motor_speed_model(p)
    wc = 2.0 * math.pi * crossover_hz
    gj = complex(control.evalfr(g, 1j * wc))
    phase_g = math.atan2(gj.imag, gj.real)  # rad, in (-pi, 0)
    # C(jw) = kp (1 + wi / (jw)) has phase atan(w/wi) - pi/2 at w = wc
    need = -math.pi + math.radians(phase_margin_deg) - phase_g
    if not (-math.pi / 2 < need < 0):
        raise ValueError(f"cannot reach {phase_margin_deg} deg phase margin at {crossover_hz} Hz "
                         "with a PI controller on this plant")
    wi = wc / math.tan(need + math.pi / 2)
    kp = 1.0 / (abs(gj) * abs(1.0 + wi / (1j * wc)))
    ki = kp * wi
    c = control.tf([kp, ki], [1.0, 0.0])
    gm, pm, _wg, wcp = control.margin(c * g)
    return PIDesign(kp=kp, ki=ki, crossover_hz=crossover_hz, phase_margin_deg=phase_margin_deg,
                    achieved_pm_deg=float(pm), achieved_crossover_hz=float(wcp) / (2 * math.pi),
                    gain_margin=float(gm))


class PISpeedController:
    """Discrete PI speed controller with back-calculation anti-windup (batched).

    ``u = kp e + I``; the command is clipped to what the amplifier can give
    at the measured speed, ``min(I_max, (V - K_b w) / R)`` (and the mirror
    bound), and the integrator is corrected by ``(u_sat - u) / T_t`` with
    the tracking time ``T_t = Ti / 2``, so it stops winding up when the amplifier saturates.

    Args:
        params: the nominal joint (design model and amplifier limits).
        target_scale: the env's speed scale (rad/s) that normalizes the
            target-speed observation.
        dt: control period, s.
        crossover_hz, phase_margin_deg: design specification.
        current_limit: the controller's own output limit, A (default: the
            amplifier's ``I_max``; a lower value models e.g. a continuous
            current rating).
    """

    def __init__(self, params: JointParams, target_scale: float, dt: float,
                 crossover_hz: float = 5.0, phase_margin_deg: float = 60.0,
                 current_limit: float | None = None) -> None:
        self.design = design_pi(params, crossover_hz, phase_margin_deg)
        self.kp = self.design.kp
        self.ki = self.design.ki
        self.tt = 0.5 * self.kp / self.ki
        self.dt = dt
        self.target_scale = target_scale
        self.i_amp = params.amplifier.current_limit
        self.i_max = self.i_amp if current_limit is None else min(float(current_limit), self.i_amp)
        self.v_max = params.amplifier.voltage_limit
        self.kb = params.motor.back_emf_constant
        self.res = params.motor.resistance
        self.integral = np.zeros(0)

    def reset(self, n: int = 1) -> None:
        self.integral = np.zeros(n)

    def predict(self, obs: np.ndarray, state: object = None,
                episode_start: np.ndarray | None = None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        obs = np.atleast_2d(np.asarray(obs, dtype=float))
        n = obs.shape[0]
        if self.integral.shape != (n,):
            self.reset(n)
        if episode_start is not None:
            self.integral[np.asarray(episode_start, dtype=bool)] = 0.0
        target = obs[:, OBS_TARGET] * self.target_scale
        speed = obs[:, OBS_SPEED] * target
        e = target - speed
        u = self.kp * e + self.integral
        hi = np.minimum(self.i_max, (self.v_max - self.kb * speed) / self.res)
        lo = np.maximum(-self.i_max, (-self.v_max - self.kb * speed) / self.res)
        u_sat = np.clip(u, np.minimum(lo, hi), hi)
        self.integral += self.dt * (self.ki * e + (u_sat - u) / self.tt)
        return (u_sat / self.i_amp)[:, None].astype(np.float32), None


class ConstantCurrent:
    """A constant normalized current command (1.0 = the amplifier's full current)."""

    def __init__(self, level: float = 1.0) -> None:
        self.level = float(level)

    def reset(self, n: int = 1) -> None:
        pass

    def predict(self, obs: np.ndarray, state: object = None,
                episode_start: np.ndarray | None = None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        n = np.atleast_2d(obs).shape[0]
        return np.full((n, 1), self.level, dtype=np.float32), None


class RippleCurrent:
    """Full current with a 2x-order ripple locked to the measured WG angle.

    ``u = 1 - a + a cos(2 theta + phi)``: the ripple is at the frequency of
    the 2x kinematic-error excitation, the phase ``phi`` (deg) sets where it
    sits against it; the mean current is ``1 - a`` of full.
    """

    def __init__(self, amplitude: float, phase_deg: float) -> None:
        self.amplitude = float(amplitude)
        self.phase = math.radians(float(phase_deg))

    def reset(self, n: int = 1) -> None:
        pass

    def predict(self, obs: np.ndarray, state: object = None,
                episode_start: np.ndarray | None = None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        obs = np.atleast_2d(np.asarray(obs, dtype=float))
        c, s = obs[:, OBS_COS], obs[:, OBS_SIN]
        c2, s2 = c * c - s * s, 2.0 * c * s  # cos, sin of 2 theta
        ripple = c2 * math.cos(self.phase) - s2 * math.sin(self.phase)
        u = 1.0 - self.amplitude + self.amplitude * ripple
        return u[:, None].astype(np.float32), None


class DampingCurrent:
    """Full current with active damping of the torsion from the torque sensor.

    ``u = 1 - a + a tanh(g (cos(phi) x + sin(phi) dx / (w_n dt)))`` with
    ``x`` the torque oscillation observation (sensor minus running mean,
    normalized) and ``dx`` its change over one call, scaled by the
    torsional frequency ``w_n`` (44 Hz) so both terms are alike in size;
    ``phi`` (deg) picks the phase of the feedback (90: on the rate of the
    torsion).
    """

    def __init__(self, amplitude: float, phase_deg: float, dt: float, gain: float = 3.0,
                 f_n: float = 44.0) -> None:
        self.amplitude = float(amplitude)
        self.phase = math.radians(float(phase_deg))
        self.gain = float(gain)
        self.scale = 1.0 / (2.0 * math.pi * f_n * dt)
        self.prev = np.zeros(0)

    def reset(self, n: int = 1) -> None:
        self.prev = np.zeros(0)

    def predict(self, obs: np.ndarray, state: object = None,
                episode_start: np.ndarray | None = None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        obs = np.atleast_2d(np.asarray(obs, dtype=float))
        x = obs[:, OBS_OSC]
        if self.prev.shape != x.shape:
            self.prev = x.copy()
        if episode_start is not None:
            first = np.asarray(episode_start, dtype=bool)
            self.prev[first] = x[first]
        dx = (x - self.prev) * self.scale
        self.prev = x.copy()
        fb = math.cos(self.phase) * x + math.sin(self.phase) * dx
        u = 1.0 - self.amplitude + self.amplitude * np.tanh(self.gain * fb)
        return u[:, None].astype(np.float32), None
