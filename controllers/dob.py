"""Disturbance observer: nominal inverse model with a Q-filter, discretized with python-control.

Nominal plant from the current command ``u`` (A) to the motor angle
``theta_m`` (rad): the rigid joint seen from the motor::

    P_n(s) = K_t / (s (J_n s + B_n))

with ``J_n`` the motor-referred total inertia (motor + output/ratio^2,
kg m^2) and ``B_n`` the viscous coefficient (N m s/rad). Whatever else acts
on the motor -- load torque through the gear, friction, spring transients --
is a disturbance ``d`` in current units, ``theta_m = P_n (u + d)``. The
observer estimates it through a low-pass ``Q(s) = 1/(tau s + 1)^2``
(relative degree 2, so ``Q/P_n`` is proper; ``tau = 1/(2 pi f_Q)``)::

    d_hat = Q P_n^-1 theta_m - Q u

and the command becomes ``u = u_c - d_hat``: below ``f_Q`` the joint
behaves like the nominal plant, the load and friction torque cancelled.
Both filters are built as continuous transfer functions and discretized
with :func:`control.sample_system` (Tustin by default). The estimate uses
the command of the previous sample (the one applied while the encoder moved
to the current reading), so there is no algebraic loop.
"""

from __future__ import annotations

import math

import control
import numpy as np

from controllers.base import Controller, Measurement, check_nonneg, check_positive

METHODS = ("tustin", "zoh", "foh", "backward_diff", "bilinear")


class DisturbanceObserver:
    """Cancel load and friction torque estimated on the motor side.

    Args:
        controller: the wrapped controller (its current command is corrected).
        inertia: J_n, nominal motor-referred inertia, kg m^2 (> 0).
        torque_constant: K_t, N m/A (> 0).
        bandwidth_hz: Q-filter corner f_Q, Hz (> 0, below Nyquist ``0.5/dt``).
        dt: sample period, s (> 0).
        damping: B_n, nominal motor-referred viscous coefficient, N m s/rad (>= 0).
        current_limit: the total command is clipped to +-this, A (> 0).
        method: discretization passed to :func:`control.sample_system`.

    Raises:
        ValueError: naming the setting (e.g. ``bandwidth_hz`` above Nyquist).
    """

    def __init__(self, controller: Controller, inertia: float, torque_constant: float,
                 bandwidth_hz: float, dt: float = 1e-3, *, damping: float = 0.0,
                 current_limit: float = math.inf, method: str = "tustin") -> None:
        self.controller = controller
        self.inertia = check_positive("inertia", inertia, "kg m^2")
        self.torque_constant = check_positive("torque_constant", torque_constant, "N m/A")
        self.dt = check_positive("dt", dt, "s")
        self.bandwidth_hz = check_positive("bandwidth_hz", bandwidth_hz, "Hz")
        nyq = 0.5 / self.dt
        if self.bandwidth_hz >= nyq:
            raise ValueError(f"bandwidth_hz must be below the Nyquist frequency {nyq:g} Hz "
                             f"(dt = {self.dt:g} s), got {bandwidth_hz!r}")
        self.damping = check_nonneg("damping", damping, "N m s/rad")
        if not float(current_limit) > 0:
            raise ValueError(f"current_limit must be > 0 A, got {current_limit!r}")
        self.current_limit = float(current_limit)
        if method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {method!r}")
        tau = 1.0 / (2.0 * math.pi * self.bandwidth_hz)
        q_den = np.polymul([tau, 1.0], [tau, 1.0])
        inv = control.tf([self.inertia, self.damping, 0.0],
                         self.torque_constant * np.asarray(q_den))  # Q / P_n
        q = control.tf([1.0], q_den)
        #: the continuous filters: Q/P_n (theta_m rad -> A) and Q (u A -> A)
        self.continuous = (inv, q)
        #: the discretized filters used each sample
        self.discrete = tuple(control.sample_system(control.ss(f), self.dt, method=method)
                              for f in (inv, q))
        self._mats = [tuple(np.asarray(m, dtype=float) for m in (d.A, d.B, d.C, d.D))
                      for d in self.discrete]
        self.reset_state()

    def reset_state(self) -> None:
        self._x: list[np.ndarray] | None = None
        self._u_prev = 0.0
        self.estimate = 0.0

    def reset(self) -> None:
        self.controller.reset()
        self.reset_state()

    def update(self, motor_angle: float) -> float:
        """Advance the observer with the new motor angle (rad); the estimate d_hat, A."""
        if self._x is None:  # start at the steady state of the first reading: no kick
            self._x = [np.linalg.solve(np.eye(a.shape[0]) - a, b[:, 0] * v)
                       for (a, b, _, _), v in zip(self._mats, (motor_angle, 0.0), strict=True)]
        y = 0.0
        for j, ((a, b, c, d), v) in enumerate(zip(self._mats, (motor_angle, self._u_prev),
                                                  strict=True)):
            x = self._x[j]
            y += float(c[0] @ x + d[0, 0] * v) * (1.0 if j == 0 else -1.0)
            self._x[j] = a @ x + b[:, 0] * v
        self.estimate = y
        return y

    def __call__(self, t: float, measurement: Measurement) -> float:
        d_hat = self.update(measurement["motor_angle"])
        u_c = self.controller(t, measurement)
        u = min(max(u_c - d_hat, -self.current_limit), self.current_limit)
        self._u_prev = u
        return u
