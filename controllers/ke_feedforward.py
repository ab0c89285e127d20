"""Kinematic-error feedforward, from a kinematic-error model identified from a record.

Identification (Tuttle §2.2; docs/physics.md, "Identification protocols"): take a
slow constant-speed run, form the measured transmission error ``motor_angle/ratio -
output_angle`` (output rad), resample it to equal WG-angle steps, and fit a
harmonic series at chosen orders of the WG angle by least squares (with an
offset and a linear trend that absorb the constant wind-up and any slow
drift). Nothing is read from the simulator's true parameters.

Feedforward: the output follows ``motor_angle/ratio - theta_ke(motor_angle)``,
so commanding the motor to ``ratio * (reference + theta_ke(theta_wg))``
makes the output follow the reference. :class:`KEFeedforward` wraps any
position controller whose motor setpoint is ``ratio * reference`` (e.g.
:class:`controllers.pid.PositionPID` with ``feedback="motor"``) and shifts
the reference it sees by ``theta_ke``.

The kinematic error also feeds torque back to the motor: through the gear
factor ``g = 1/ratio - theta_ke'(theta_wg)`` (docs/physics.md eqs. (2), (8),
(11)) the motor carries ``g`` times every torque at the tooth mesh, the
flexspline torque ``T_k`` and, when the transmission friction sits in the
mesh, that friction too. A flexspline torque sensor reads ``T_k`` but not the
mesh friction (Tuttle 1992 §3, models 2 and 5), so
:func:`identify_mesh_friction` estimates it from the same record, from the
motor's torque balance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from controllers.base import (
    Controller,
    Measurement,
    check_finite,
    check_nonneg,
    check_orders,
    check_positive,
)


@dataclass(frozen=True)
class KEModel:
    """``theta_ke(theta_wg) = sum_n a_n cos(n theta_wg) + b_n sin(n theta_wg)`` (output rad).

    Attributes:
        orders: orders of the WG angle (cycles per WG revolution).
        cos, sin: coefficients a_n, b_n, output rad.
        offset: mean transmission error during identification (wind-up and
            encoder offset), output rad; not part of :meth:`__call__`.
        residual_rms: RMS of the fit residual on the resampled data, output rad.
        compliance: wind-up per N m of flexspline torque, output rad/(N m),
            when the fit included the torque-sensor column (else 0); the
            offset is then the wind-up at zero torque.
    """

    orders: tuple[float, ...]
    cos: tuple[float, ...]
    sin: tuple[float, ...]
    offset: float = 0.0
    residual_rms: float = 0.0
    compliance: float = 0.0

    def __post_init__(self) -> None:
        check_orders("orders", self.orders)
        if not len(self.cos) == len(self.sin) == len(self.orders):
            raise ValueError("cos and sin must have one coefficient per order")

    def __call__(self, theta_wg: float | np.ndarray) -> Any:
        """Kinematic error at WG angle ``theta_wg`` (rad), output rad."""
        th = np.asarray(theta_wg, dtype=float)
        out = np.zeros_like(th)
        for n, a, b in zip(self.orders, self.cos, self.sin, strict=True):
            out = out + a * np.cos(n * th) + b * np.sin(n * th)
        return float(out) if out.ndim == 0 else out

    def scalar(self, theta_wg: float) -> float:
        """Fast scalar evaluation, output rad."""
        out = 0.0
        for n, a, b in zip(self.orders, self.cos, self.sin, strict=True):
            out += a * math.cos(n * theta_wg) + b * math.sin(n * theta_wg)
        return out

    def slope(self, theta_wg: float) -> float:
        """d theta_ke / d theta_wg at ``theta_wg`` (output rad per WG rad)."""
        out = 0.0
        for n, a, b in zip(self.orders, self.cos, self.sin, strict=True):
            out += n * (b * math.cos(n * theta_wg) - a * math.sin(n * theta_wg))
        return out

    def amplitudes(self) -> dict[float, float]:
        """Amplitude per order, output rad."""
        return {n: math.hypot(a, b) for n, a, b in zip(self.orders, self.cos, self.sin,
                                                       strict=True)}

    def peak_to_peak(self, n_points: int = 4096, revolutions: float = 1.0) -> float:
        """Peak-to-peak of the model over ``revolutions`` WG turns, output rad."""
        th = np.linspace(0.0, 2 * math.pi * revolutions, n_points)
        v = self(th)
        return float(v.max() - v.min())


def resample_by_angle(motor_angle: np.ndarray, values: np.ndarray,
                      samples_per_rev: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """``values`` on an equal WG-angle grid (rad), averaging samples at the same count.

    The motor angle must move one way (a constant-speed run); samples where
    the encoder reads the same count are averaged first.

    Returns:
        (grid angles, rad; resampled values).
    """
    if samples_per_rev < 8:
        raise ValueError(f"samples_per_rev must be >= 8, got {samples_per_rev!r}")
    th = np.asarray(motor_angle, dtype=float)
    v = np.asarray(values, dtype=float)
    if th.shape != v.shape or th.ndim != 1 or th.size < 2:
        raise ValueError("motor_angle and values must be 1-D arrays of the same length")
    direction = np.sign(th[-1] - th[0])
    if direction == 0:
        raise ValueError("motor_angle: the motor does not move; identification needs a "
                         "constant-speed run")
    steps = np.diff(th) * direction
    if np.mean(steps < 0) > 0.01:
        raise ValueError("motor_angle: the motor reverses during the record; identification "
                         "needs a run in one direction")
    uniq, inv = np.unique(th, return_inverse=True)
    mean = np.bincount(inv, weights=v) / np.bincount(inv)
    span = uniq[-1] - uniq[0]
    if span < 2 * 2 * math.pi:
        raise ValueError(f"motor_angle: the record covers {span / (2 * math.pi):.2f} WG "
                         f"revolutions; identification needs at least 2")
    n = int(span / (2 * math.pi) * samples_per_rev)
    grid = uniq[0] + np.arange(n) * (2 * math.pi / samples_per_rev)
    return grid, np.interp(grid, uniq, mean)


def _ratio(record: Any, ratio: float | None) -> float:
    if ratio is None:
        try:
            ratio = float(record.meta["ratio"])
        except (KeyError, TypeError, ValueError, AttributeError):
            raise ValueError("ratio: not given and not in the record metadata") from None
    return check_positive("ratio", ratio)


def identify_ke(record: Any, orders: tuple[float, ...] | list[float] = (1, 2, 4), *,
                ratio: float | None = None, samples_per_rev: int = 256,
                settle: float = 0.0, torque: bool = False,
                output_offset: float = 0.0) -> KEModel:
    """Fit a :class:`KEModel` to a slow constant-speed record.

    Args:
        record: a :class:`hdgym.record.Record` (or anything with ``time``,
            ``motor_angle``, ``output_angle`` arrays and ``meta``).
        orders: orders of the WG angle to fit (positive; non-integer
            orders such as the flexspline line ``2 (1 + 1/N)`` are allowed
            if the record is long enough to separate them).
        ratio: motor angle per output angle (default: ``record.meta["ratio"]``).
        samples_per_rev: resampling grid, points per WG revolution.
        settle: seconds at the start to drop (acceleration transient).
        torque: also regress on the torque-sensor column ``output_torque``
            (N m) to separate the wind-up, which follows the slowly varying
            friction torque, from the kinematic error (sets ``compliance``).
        output_offset: added to the recorded output angle, rad: half a count
            for an encoder that floors to whole counts, so that ``offset`` is
            the transmission error of the true output (it reads half a count
            low on average, 8 arcsec on an 80,000-count encoder).

    Raises:
        ValueError: on bad orders, a missing ratio, or a record that is too
            short or not monotonic.
    """
    orders = check_orders("orders", orders)
    ratio = _ratio(record, ratio)
    output_offset = check_finite("output_offset", output_offset)
    t = np.asarray(record.time, dtype=float)
    keep = t >= t[0] + settle
    th_m = np.asarray(record.motor_angle, dtype=float)[keep]
    th_o = np.asarray(record.output_angle, dtype=float)[keep] + output_offset
    grid, err = resample_by_angle(th_m, th_m / ratio - th_o, samples_per_rev)
    x = (grid - grid[0]) / (grid[-1] - grid[0])
    cols = [np.ones_like(grid)] if torque else [np.ones_like(grid), x]
    if torque:
        tk = getattr(record, "output_torque", None)
        if tk is None:
            raise ValueError("torque: the record has no output_torque column")
        _, tk_grid = resample_by_angle(th_m, np.asarray(tk, dtype=float)[keep], samples_per_rev)
        cols.append(tk_grid)
    n0 = len(cols)
    for n in orders:
        cols += [np.cos(n * grid), np.sin(n * grid)]
    a = np.column_stack(cols)
    coef, *_ = np.linalg.lstsq(a, err, rcond=None)
    resid = err - a @ coef
    offset = float(coef[0]) if torque else float(coef[0] + 0.5 * coef[1])
    return KEModel(orders=orders, cos=tuple(float(c) for c in coef[n0::2]),
                   sin=tuple(float(c) for c in coef[n0 + 1::2]), offset=offset,
                   residual_rms=float(np.sqrt(np.mean(resid ** 2))),
                   compliance=float(coef[1]) if torque else 0.0)


@dataclass(frozen=True)
class MeshFriction:
    """Friction level in the tooth mesh against the output angle, N m output-referred.

    ``F(theta_o) = level + sum_k a_k cos(k theta_o) + b_k sin(k theta_o)``: a
    constant part and, at ``orders`` per output revolution, the cyclic part
    of Tuttle's transmission friction (1992, eq. 3.24). Valid near the speed
    it was identified at (the level includes the viscous part there).
    """

    level: float
    orders: tuple[float, ...] = ()
    cos: tuple[float, ...] = ()
    sin: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        check_finite("level", self.level)
        if self.orders:
            check_orders("orders", self.orders)
        if not len(self.cos) == len(self.sin) == len(self.orders):
            raise ValueError("cos and sin must have one coefficient per order")

    def __call__(self, output_angle: float) -> float:
        """Friction level at ``output_angle`` (rad), N m, never below zero."""
        out = self.level
        for k, a, b in zip(self.orders, self.cos, self.sin, strict=True):
            out += a * math.cos(k * output_angle) + b * math.sin(k * output_angle)
        return max(out, 0.0)


def identify_mesh_friction(record: Any, model: KEModel, *, torque_constant: float,
                           motor_inertia: float, ratio: float | None = None,
                           settle: float = 0.0,
                           output_orders: tuple[float, ...] | list[float] = ()
                           ) -> MeshFriction:
    """Transmission friction in the tooth mesh that the torque sensor does not read.

    The motor's torque balance (docs/physics.md eq. (11), the mesh friction
    reflected by eq. (8))::

        K_t i - J_m theta_m'' - g T_k = F_in + g F_mesh,   g = 1/ratio - theta_ke'(theta_wg)

    puts ``-F_mesh theta_ke'`` into the current at the kinematic-error
    orders. A least-squares fit of the left side (current command, second
    difference of the motor angle, torque sensor, identified ``theta_ke'``) on
    ``[1, t, theta_ke', theta_ke' cos(k theta_o), theta_ke' sin(k theta_o)]``
    returns ``F_mesh(theta_o)`` over the record at its speed (output-referred,
    positive when it opposes the motion). Subtracting the motor's inertia
    torque and the sensor's torque first keeps the motor's acceleration and
    the output's vibration out of the fit: both rise with the order and
    would otherwise inflate the estimate (on tuttle-joint3 by up to half).

    Args:
        record: a constant-speed record with ``current_command``,
            ``motor_angle``, ``output_angle`` and ``output_torque`` columns
            (the one :func:`identify_ke` fitted ``model`` to).
        model: the identified kinematic error.
        torque_constant: K_t, N m/A (> 0), nominal.
        motor_inertia: J_m, the motor and WG inertia, kg m^2 (>= 0), nominal.
        ratio: motor angle per output angle (default: ``record.meta["ratio"]``).
        settle: seconds at the start to drop.
        output_orders: orders per output revolution of the cyclic part (none:
            a constant level); the record should cover about a revolution of
            the output for them.

    Raises:
        ValueError: a missing column, a bad constant or order, or a record
            whose motor does not turn.
    """
    ratio = _ratio(record, ratio)
    kt = check_positive("torque_constant", torque_constant, "N m/A")
    jm = check_nonneg("motor_inertia", motor_inertia, "kg m^2")
    k_orders = check_orders("output_orders", output_orders) if len(output_orders) else ()
    cols = {}
    for name in ("current_command", "output_torque"):
        col = getattr(record, "columns", {}).get(name)
        if col is None:
            raise ValueError(f"record: mesh-friction identification needs a {name!r} column")
        cols[name] = np.asarray(col, dtype=float)
    t = np.asarray(record.time, dtype=float)
    th = np.asarray(record.motor_angle, dtype=float)
    direction = np.sign(th[-1] - th[0])
    if direction == 0:
        raise ValueError("motor_angle: the motor does not move; identification needs a "
                         "constant-speed run")
    acc = np.gradient(np.gradient(th, t), t)
    slope = np.asarray([model.slope(x) for x in th])
    y = kt * cols["current_command"] - jm * acc - (1.0 / ratio - slope) * cols["output_torque"]
    th_o = np.asarray(record.output_angle, dtype=float)
    keep = t >= t[0] + settle
    a = [np.ones_like(t), t - t[0], slope]
    for k in k_orders:
        a += [slope * np.cos(k * th_o), slope * np.sin(k * th_o)]
    coef, *_ = np.linalg.lstsq(np.column_stack(a)[keep], y[keep], rcond=None)
    f = -coef[2:] * direction
    return MeshFriction(level=float(f[0]), orders=k_orders,
                        cos=tuple(float(c) for c in f[1::2]),
                        sin=tuple(float(c) for c in f[2::2]))


class KEFeedforward:
    """Correct the motor reference by ``ratio * theta_ke(theta_wg)`` so the output follows.

    Wraps a controller whose motor setpoint is ``ratio * reference``: it sees
    ``reference + theta_ke(theta_wg_ref)``, where ``theta_wg_ref`` solves
    ``theta_wg/ratio - theta_ke(theta_wg) = reference`` (two fixed-point
    passes; the correction is far smaller than a KE period).

    Two optional terms use the same identified model:

    * ``offset=True`` also adds the model's ``offset``, the mean transmission
      error of the identification run: the wind-up at that speed and load
      (valid only near them). Fit the model with ``torque=False`` for this:
      feeding the measured torque back through the identified compliance
      was tried and made tracking worse (the correction moves the motor,
      which changes the torque it is computed from);
    * ``torque_constant`` (N m/A) adds the current ``-T_k theta_ke'(theta_wg)/K_t``
      that cancels the torque the kinematic error feeds back to the motor
      (power balance, docs/physics.md eqs. (2) and (11): the motor sees
      ``T_k (1/ratio - theta_ke')``), with ``T_k`` from the torque sensor (``output_torque``);
    * ``mesh_friction`` (with ``torque_constant``): the friction in the tooth
      mesh (:class:`MeshFriction` from :func:`identify_mesh_friction`), which
      the motor feels through the same factor but the sensor does not read;
      it joins ``T_k`` in the torque term, at the reference's output angle
      and with the sign of its speed (nothing while the reference stands
      still).

    * ``load_inertia`` (kg m^2, motor-referred, with ``torque_constant``):
      the wrapped controller's inertia feedforward treats the shifted
      reference as rigid motion of motor and load, but the correction moves
      only the motor (the output moves smoothly); the current
      ``-load_inertia * ratio * c''/K_t`` removes the load's share.

    Args:
        controller: the position controller to wrap.
        model: the identified kinematic error.
        ratio: motor angle per output angle.
        offset: add the identified mean wind-up.
        torque_constant: enables the torque term, N m/A (> 0).
        load_inertia: load share of the wrapped feedforward's inertia,
            ``J_o/ratio^2``, kg m^2 (>= 0; needs ``torque_constant``).
        mesh_friction: the friction in the mesh, a :class:`MeshFriction`
            (N m output-referred; needs ``torque_constant``).
        dt: sample period for ``c''``, s.
    """

    def __init__(self, controller: Controller, model: KEModel, ratio: float, *,
                 offset: bool = False, torque_constant: float | None = None,
                 load_inertia: float = 0.0, mesh_friction: MeshFriction | None = None,
                 dt: float = 1e-3) -> None:
        self.controller = controller
        self.model = model
        self.ratio = check_positive("ratio", ratio)
        self.offset = bool(offset)
        self.torque_constant = (None if torque_constant is None
                                else check_positive("torque_constant", torque_constant, "N m/A"))
        self.load_inertia = check_nonneg("load_inertia", load_inertia, "kg m^2")
        if self.load_inertia > 0 and self.torque_constant is None:
            raise ValueError("load_inertia: needs torque_constant")
        self.mesh_friction = mesh_friction
        if mesh_friction is not None and self.torque_constant is None:
            raise ValueError("mesh_friction: needs torque_constant")
        self.dt = check_positive("dt", dt, "s")
        self.reset_state()

    def reset_state(self) -> None:
        self.last_correction = 0.0
        self._c: list[float] = []
        self._ref: float | None = None

    def reset(self) -> None:
        self.controller.reset()
        self.reset_state()

    def correction(self, reference: float) -> float:
        """theta_ke at the WG angle that puts the output at ``reference``, output rad.

        With ``offset`` the identified mean wind-up is added.
        """
        c = 0.0
        for _ in range(2):
            c = self.model.scalar(self.ratio * (reference + c))
        return c + (self.model.offset if self.offset else 0.0)

    def __call__(self, t: float, measurement: Measurement) -> float:
        ref = measurement["reference"]
        self.last_correction = self.correction(ref)
        m = dict(measurement)
        m["reference"] = ref + self.last_correction
        u = self.controller(t, m)
        if self.torque_constant is not None:
            slope = self.model.slope(measurement["motor_angle"])
            mesh = measurement["output_torque"]
            if self.mesh_friction is not None and self._ref is not None and ref != self._ref:
                mesh += math.copysign(self.mesh_friction(ref), ref - self._ref)
            self._ref = ref
            u -= mesh * slope / self.torque_constant
            self._c = (self._c + [self.last_correction])[-3:]
            if self.load_inertia > 0 and len(self._c) == 3:
                acc = (self._c[2] - 2 * self._c[1] + self._c[0]) / self.dt ** 2
                u -= self.load_inertia * self.ratio * acc / self.torque_constant
        return u
