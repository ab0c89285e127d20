"""Discrete PID with anti-windup, filtered derivative, output limits and bumpless reset.

:class:`PID` is the bare law on numbers; :class:`PositionPID` and
:class:`Cascade` turn it into joint controllers (measurements in, current
command out, A).

The law, sampled every ``dt`` s::

    e      = setpoint - measurement
    v      = kp e + I + D + feedforward                (unsaturated output)
    u      = clip(v, u_min, u_max)
    D_k    = tf/(tf+dt) D_{k-1} + kd/(tf+dt) (x_k - x_{k-1})   (backward Euler of
             kd s/(tf s + 1); x = -measurement or e, see ``derivative_on``)
    I     += ki dt e + dt/tt (u - v)                  (back-calculation), or
    I     += ki dt e  unless u is saturated and e pushes further (clamping)

With ``ki = 0`` the integral stays where it is (a PD law): back-calculation
alone would otherwise turn saturation into a lasting offset.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import Any

from controllers.base import Measurement, check_finite, check_nonneg, check_positive

ANTI_WINDUP = ("back_calculation", "clamping", "none")
DERIVATIVE_ON = ("measurement", "error")
FEEDBACK = ("motor", "output")


class PID:
    """A discrete PID controller.

    Args:
        kp: proportional gain (output units per measurement unit, >= 0).
        ki: integral gain (per s, >= 0).
        kd: derivative gain (s, >= 0).
        dt: sample period, s (> 0).
        tf: derivative filter time constant, s (> 0; default ``max(kd/kp/8, 2 dt)``).
        u_min, u_max: output limits (u_min < u_max; default unlimited).
        anti_windup: ``"back_calculation"`` (default), ``"clamping"`` or ``"none"``.
        tt: back-calculation tracking time constant, s (> 0; default
            ``sqrt(Ti Td)`` or ``Ti`` without derivative, Åström & Hägglund).
        derivative_on: ``"measurement"`` (no kick on setpoint steps) or ``"error"``.

    Raises:
        ValueError: naming the setting, for negative gains, ``dt <= 0``,
            ``u_min >= u_max`` or an unknown mode.
    """

    def __init__(self, kp: float, ki: float = 0.0, kd: float = 0.0, *, dt: float = 1e-3,
                 tf: float | None = None, u_min: float = -math.inf, u_max: float = math.inf,
                 anti_windup: str = "back_calculation", tt: float | None = None,
                 derivative_on: str = "measurement") -> None:
        self.dt = check_positive("dt", dt, "s")
        self.kp = check_nonneg("kp", kp)
        self.ki = check_nonneg("ki", ki, "1/s")
        self.kd = check_nonneg("kd", kd, "s")
        if anti_windup not in ANTI_WINDUP:
            raise ValueError(f"anti_windup must be one of {ANTI_WINDUP}, got {anti_windup!r}")
        if derivative_on not in DERIVATIVE_ON:
            raise ValueError(f"derivative_on must be one of {DERIVATIVE_ON}, got {derivative_on!r}")
        self.anti_windup = anti_windup
        self.derivative_on = derivative_on
        if math.isnan(u_min) or math.isnan(u_max) or not u_min < u_max:
            raise ValueError(f"u_min must be < u_max, got u_min={u_min!r}, u_max={u_max!r}")
        self.u_min = float(u_min)
        self.u_max = float(u_max)
        if tf is None:
            tf = max(self.kd / self.kp / 8.0 if self.kp > 0 else 0.0, 2.0 * self.dt)
        self.tf = check_positive("tf", tf, "s")
        if tt is None:
            if self.ki > 0 and self.kp > 0:
                ti = self.kp / self.ki
                td = self.kd / self.kp
                tt = math.sqrt(ti * td) if td > 0 else ti
            else:
                tt = 10.0 * self.dt
            tt = max(tt, self.dt)
        self.tt = check_positive("tt", tt, "s")
        self.integral = 0.0
        self.derivative = 0.0
        self._x_prev: float | None = None
        self.output = 0.0

    def reset(self, output: float = 0.0, setpoint: float = 0.0, measurement: float = 0.0,
              feedforward: float = 0.0) -> None:
        """Bumpless reset: the next call with the same inputs returns ``output``.

        The integral is set to ``output - kp e - feedforward``, the derivative
        memory to the current measurement (so no derivative kick).
        """
        e = setpoint - measurement
        self.integral = check_finite("output", output) - self.kp * e - feedforward
        self.derivative = 0.0
        self._x_prev = -measurement if self.derivative_on == "measurement" else e
        self.output = min(max(output, self.u_min), self.u_max)

    def set_gains(self, kp: float, ki: float, kd: float, setpoint: float = 0.0,
                  measurement: float = 0.0) -> None:
        """Change gains without a bump in the output (integral re-balanced)."""
        e = setpoint - measurement
        before = self.kp * e + self.integral + self.derivative
        self.kp = check_nonneg("kp", kp)
        self.ki = check_nonneg("ki", ki, "1/s")
        self.kd = check_nonneg("kd", kd, "s")
        self.integral = before - self.kp * e - self.derivative

    def update(self, setpoint: float, measurement: float, feedforward: float = 0.0) -> float:
        """One sample: the limited output."""
        e = setpoint - measurement
        x = -measurement if self.derivative_on == "measurement" else e
        if self._x_prev is None:
            self._x_prev = x
        a = self.tf / (self.tf + self.dt)
        self.derivative = a * self.derivative + self.kd / (self.tf + self.dt) * (x - self._x_prev)
        self._x_prev = x
        v = self.kp * e + self.integral + self.derivative + feedforward
        u = min(max(v, self.u_min), self.u_max)
        if self.ki == 0.0:
            pass  # no integral action: nothing to wind up (back-calculation would make one)
        elif self.anti_windup == "back_calculation":
            self.integral += self.ki * self.dt * e + self.dt / self.tt * (u - v)
        elif self.anti_windup == "clamping":
            pushing = (u >= self.u_max and e > 0) or (u <= self.u_min and e < 0)
            if not pushing:
                self.integral += self.ki * self.dt * e
        else:
            self.integral += self.ki * self.dt * e
        self.output = u
        return u


def _check_feedback(feedback: str) -> str:
    if feedback not in FEEDBACK:
        raise ValueError(f"feedback must be one of {FEEDBACK}, got {feedback!r}")
    return feedback


class PositionPID:
    """Position control of the joint with one PID whose output is the current, A.

    ``feedback="motor"`` (semi-closed loop, the usual robot joint): the
    setpoint is the motor reference ``ratio * reference`` and the PID acts on
    the motor encoder, so the output carries the kinematic error and the
    torsion. ``feedback="output"``: the PID acts on the output encoder.

    Args:
        pid: the law; its units are A per rad of the fed-back angle.
        ratio: motor angle per output angle.
        feedback: ``"motor"`` or ``"output"``.
        inertia_feedforward: A per (motor rad/s^2) times the reference
            acceleration (0 = off), e.g. ``J_total / K_t``.
        friction_feedforward: A per (motor rad/s) times the reference speed.
        loop_filter: a :class:`controllers.filters.DiscreteFilter` in series
            with the PID output (e.g. a notch at the resonance); the
            feedforward bypasses it.
    """

    def __init__(self, pid: PID, ratio: float, feedback: str = "motor",
                 inertia_feedforward: float = 0.0, friction_feedforward: float = 0.0,
                 loop_filter: Any = None) -> None:
        self.pid = pid
        self.ratio = check_positive("ratio", ratio)
        self.feedback = _check_feedback(feedback)
        self.inertia_feedforward = check_nonneg("inertia_feedforward", inertia_feedforward)
        self.friction_feedforward = check_nonneg("friction_feedforward", friction_feedforward)
        self.loop_filter = loop_filter
        self._ref = _RefRate(pid.dt)

    def reset(self) -> None:
        self.pid.reset()
        self._ref.reset()
        if self.loop_filter is not None:
            self.loop_filter.reset()

    def without_integral(self) -> PositionPID:
        """A fresh copy with ``ki = 0`` (a PD law; same filter and feedforward).

        For an outer loop around a disturbance observer, which already acts
        as integral action: a second integrator makes the loop hunt against
        static friction.
        """
        pd = copy.deepcopy(self)
        pd.pid.set_gains(pd.pid.kp, 0.0, pd.pid.kd)
        pd.reset()
        return pd

    def __call__(self, t: float, measurement: Measurement) -> float:
        ref = measurement["reference"]
        w, a = self._ref.update(ref)
        ff = self.ratio * (self.inertia_feedforward * a + self.friction_feedforward * w)
        if self.feedback == "motor":
            u = self.pid.update(self.ratio * ref, measurement["motor_angle"])
        else:
            u = self.pid.update(ref, measurement["output_angle"])
        if self.loop_filter is not None:
            u = self.loop_filter.step(u)
        return min(max(u + ff, self.pid.u_min), self.pid.u_max)


class _RefRate:
    """Reference speed and acceleration by backward differences, rad/s and rad/s^2."""

    def __init__(self, dt: float) -> None:
        self.dt = dt
        self.reset()

    def reset(self) -> None:
        self.prev: float | None = None
        self.w = 0.0

    def update(self, ref: float) -> tuple[float, float]:
        if self.prev is None:
            self.prev = ref
        w = (ref - self.prev) / self.dt
        a = (w - self.w) / self.dt
        self.prev, self.w = ref, w
        return w, a


@dataclass
class Cascade:
    """Cascaded position–velocity loops.

    The outer :class:`PID` turns the position error (output rad, or motor
    rad with ``feedback="motor"``) into a motor-speed reference, rad/s; the
    inner one turns the motor-speed error into the current, A. The inner
    loop uses ``motor_velocity`` (counts differenced by the sensor bank),
    optionally low-passed at ``velocity_filter_hz``. The reference speed
    is fed forward (``ratio * d reference/dt``) when ``velocity_feedforward``.

    Args:
        position: outer law, (rad/s of the motor) per rad of position error.
        velocity: inner law, A per rad/s; carries the current limits.
        ratio: motor angle per output angle.
        feedback: ``"output"`` (output encoder) or ``"motor"`` for the outer loop.
        velocity_feedforward: add the reference speed to the outer loop's output.
        velocity_filter_hz: first-order low-pass on the measured motor speed,
            Hz (0 = off; must be below the Nyquist frequency).
    """

    position: PID
    velocity: PID
    ratio: float
    feedback: str = "output"
    velocity_feedforward: bool = True
    velocity_filter_hz: float = 0.0

    def __post_init__(self) -> None:
        self.ratio = check_positive("ratio", self.ratio)
        _check_feedback(self.feedback)
        f = check_nonneg("velocity_filter_hz", self.velocity_filter_hz, "Hz")
        if f > 0.5 / self.velocity.dt:
            raise ValueError(f"velocity_filter_hz must be below the Nyquist frequency "
                             f"{0.5 / self.velocity.dt:g} Hz, got {f!r}")
        self._alpha = 1.0 - math.exp(-2 * math.pi * f * self.velocity.dt) if f > 0 else 1.0
        self._ref = _RefRate(self.position.dt)
        self._w = 0.0

    def reset(self) -> None:
        self.position.reset()
        self.velocity.reset()
        self._ref.reset()
        self._w = 0.0

    def __call__(self, t: float, measurement: Measurement) -> float:
        ref = measurement["reference"]
        w_ref_out, _ = self._ref.update(ref)
        ff = self.ratio * w_ref_out if self.velocity_feedforward else 0.0
        if self.feedback == "output":
            w_ref = self.position.update(ref, measurement["output_angle"], ff)
        else:
            w_ref = self.position.update(self.ratio * ref, measurement["motor_angle"], ff)
        self._w += self._alpha * (measurement["motor_velocity"] - self._w)
        return self.velocity.update(w_ref, self._w)
