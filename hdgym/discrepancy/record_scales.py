"""Sizes read from a record: friction held at rest, typical torque/speed/torsion, the
amplifier's clip levels, and the order-line guesses that start kinematic error and friction
ripple (:class:`.effect.Scales`)."""

from __future__ import annotations

import numpy as np

from hdgym.params import JointParams

from . import residuals as R
from .effect import BAND_SPREAD, Scales
from .friction_effects import RIPPLE_ORDERS
from .gear_effects import ke_lines
from .restarts import REST_PAUSE, pauses

CLIP_BAND = 0.9
"""Samples whose measured magnitude is within this share of the largest read a clip level
(:func:`clip_level`); below it the other limit (or the load) held the signal."""


def clip_level(measured: np.ndarray, asked: np.ndarray) -> tuple[float, bool]:
    """The level an amplifier limit clipped a signal at, and whether it clipped at all.

    The largest measured magnitude sits a noise peak above the limit; where the amplifier
    was asked for more than that and the measured magnitude stayed near the top (within
    :data:`CLIP_BAND`; lower, the other limit held it), the signal sat at its limit, so the
    median measured magnitude there reads the limit without the noise's bias. Nothing
    asked for beyond the peak: nothing clipped, and the largest measured magnitude is
    returned (a bound the record never reached). Units are the signals'.
    """
    m = np.abs(np.asarray(measured, dtype=float))
    peak = float(np.max(m)) if m.size else 0.0
    held = (np.abs(np.asarray(asked, dtype=float)) > peak) & (m >= CLIP_BAND * peak)
    return (float(np.median(m[held])), True) if held.any() else (peak, False)


class RecordScales:
    """The part of :class:`.problem.Problem` that reads sizes from its record."""

    params: JointParams
    raw: R.Raw
    names: tuple[str, ...]
    measured: dict[str, np.ndarray]
    context: R.Context
    dt: float
    cutoff: float
    ratio: float
    u: np.ndarray
    t_ext: np.ndarray
    locked: bool
    inverse: bool

    def _held(self, speed: np.ndarray) -> dict[str, R.Held]:
        """The torque each friction side holds while it sticks (see :class:`.residuals.Held`).

        With a compared torque sensor the two sides separate: the output side holds
        the transmitted torque minus the load, the motor side the motor torque minus
        the transmitted torque through the gear. Without one, the motor torque
        through the gear minus the load is what the joint holds as a whole
        (``lumped``). Empty in the inverse comparison and when nothing pauses.
        """
        if self.inverse:
            return {}
        raw, p, r, dt = self.raw, self.params, self.ratio, self.dt
        m = int(round(REST_PAUSE / dt))
        motor_stuck = pauses(np.asarray(raw.motor_angle, dtype=float), m)
        out: dict[str, R.Held] = {}
        sensor = "output_torque" in self.names
        t_k = np.asarray(raw.output_torque, dtype=float) if sensor else None
        if raw.motor_current is not None:
            kt_i = p.motor.torque_constant * np.asarray(raw.motor_current, dtype=float)
        else:
            kt_i = p.motor.torque_constant * self.u
        if t_k is not None and motor_stuck.any():
            out["input"] = R.Held(kt_i - t_k / r, speed, motor_stuck)
        if not self.locked:
            th_o = (np.asarray(raw.output_angle, dtype=float) if raw.output_angle is not None
                    else np.asarray(raw.motor_angle, dtype=float) / r)
            load = p.load.torque + self.t_ext
            if p.load.gravity:
                load = load + p.load.gravity * np.sin(th_o)
            out_stuck = (pauses(th_o, m) if raw.output_angle is not None else motor_stuck)
            if out_stuck.any():
                held = t_k - load if t_k is not None else kt_i * r - load
                out["output" if t_k is not None else "lumped"] = R.Held(held, speed / r,
                                                                        out_stuck)
        return out

    def _scales(self) -> Scales:
        p = self.params
        c = self.context
        kt_out = p.motor.torque_constant * self.ratio
        cur = float(np.max(np.abs(self.u))) or 1e-6
        torque = kt_out * max(float(np.quantile(np.abs(self.u), 0.95)), 1e-3 * cur)
        if c.torque is not None and self.raw.output_torque is not None:
            torque = max(torque, float(np.quantile(np.abs(c.torque), 0.95)))
        speed = max(float(np.quantile(np.abs(c.speed), 0.95)) / self.ratio, 1e-6)
        torsion = (float(np.quantile(np.abs(c.torsion), 0.95)) if c.torsion is not None
                   else torque / p.compliance.stiffness)
        torsion = max(torsion, 1e-9)
        cm, unreached = 0.0, False
        if self.raw.motor_current is not None:  # the amplifier's limits as the record shows
            i_m = np.asarray(self.raw.motor_current, dtype=float)
            cm, _ = clip_level(i_m, self.u)
            r_m, k_b = p.motor.resistance, p.motor.back_emf_constant
            volt, reached = clip_level(r_m * i_m + k_b * c.speed,
                                       r_m * np.clip(self.u, -cm, cm) + k_b * c.speed)
            unreached = not reached
        else:
            volt = float(np.max(np.abs(p.motor.resistance * self.u
                                       + p.motor.back_emf_constant * c.speed)))
        te = float(np.std(self.measured["transmission_error"])) \
            if "transmission_error" in self.measured else 0.0
        static = tuple((side, *lv) for side, h in c.held.items()
                       if (lv := R.friction_levels(h, self.dt, self.cutoff)) is not None)
        return Scales(torque=torque, speed=speed, torsion=torsion, current=cur,
                      current_measured=cm, voltage=volt,
                      voltage_unreached=unreached, locked=self.locked,
                      inverse=self.inverse, transmission_error=te, ke=self._ke_guess(),
                      ripple=self._ripple_guess(), static=static, **self._facts(cur))

    def _facts(self, largest_command: float) -> dict:
        """What the record shows (the :class:`.effect.Condition` checks read these)."""
        p, c = self.params, self.context
        w = np.abs(c.speed)
        typical = float(np.quantile(w, 0.9))
        moving = w > 0.1 * typical if typical > 0 else np.zeros(w.size, dtype=bool)
        sgn = np.sign(c.speed[moving])
        reversals = int(np.count_nonzero(sgn[1:] != sgn[:-1]))
        wm = w[moving]
        spread, band_time = 1.0, 0.0
        if wm.size > 10:
            top = float(np.quantile(wm, 0.9))
            spread = top / max(float(np.quantile(wm, 0.1)), 1e-12)
            # how long the record moves in the lower part of the band (a run-up's passage)
            band_time = float(np.count_nonzero(wm < top / BAND_SPREAD)) * self.dt
        standstills = 0 if self.inverse else int(np.size(getattr(self, "rest_points", ())))
        kt_out = p.motor.torque_constant * self.ratio
        i_peak = p.amplifier.current_limit
        if not i_peak < 1e5 or "amplifier_saturation" not in p.effects:
            i_peak = largest_command
        peak = max(kt_out * i_peak, 1e-12)
        sensor = self.raw.output_torque is not None
        if sensor or self.locked:
            transmitted = np.abs(c.torque)
        else:  # load torque plus what accelerates the load (the model's load inertia)
            acc = np.gradient(c.speed, self.dt) / self.ratio
            transmitted = np.abs(self.t_ext + p.load.torque + p.load.inertia * acc)
        return {"moving": float(np.mean(moving)), "reversals": reversals,
                "standstills": standstills, "wg_turns": float(np.ptp(c.theta_m)) / (2 * np.pi),
                "speed_spread": spread, "band_time": band_time,
                "torsion_measured": bool(self.locked or sensor
                                         or "transmission_error" in self.names),
                "te_measured": "transmission_error" in self.names,
                "torque_share": float(np.max(np.abs(c.torque))) / peak,
                "moving_torque_share": (float(np.quantile(transmitted[moving], 0.9)) / peak
                                        if moving.any() else 0.0)}

    def _harmonics(self, y: np.ndarray, orders: tuple[float, ...],
                   keep: np.ndarray | None = None) -> tuple[tuple[float, float, float], ...]:
        """``(order, a, b)`` of ``y ~ a sin(n theta_m) + b cos(n theta_m) + c0 + c1 t``."""
        th = self.context.theta_m
        t = self.context.time
        cols = [np.ones_like(t), (t - t.mean()) / (np.ptp(t) or 1.0)]
        for n in orders:
            cols += [np.sin(n * th), np.cos(n * th)]
        X = np.column_stack(cols)
        if keep is not None:
            X, y = X[keep], y[keep]
        if y.size < 4 * X.shape[1]:
            return ()
        beta, *_ = np.linalg.lstsq(X, y, rcond=None)
        return tuple((float(n), float(beta[2 + 2 * k]), float(beta[3 + 2 * k]))
                     for k, n in enumerate(orders))

    def _ke_guess(self) -> tuple[tuple[float, str, float, float], ...]:
        span = float(np.ptp(self.context.theta_m))
        if "transmission_error" not in self.measured or span < 4 * np.pi:
            return ()
        lines = ke_lines(self.params, span)
        fit = self._harmonics(self.measured["transmission_error"],
                              tuple(eff for _, _, eff in lines))
        # TE = output - motor/ratio = -(ke + torsion): the KE is minus the order lines
        return tuple((o, port, -a, -b)
                     for (o, port, _), (_, a, b) in zip(lines, fit, strict=True))

    def _ripple_guess(self) -> tuple[tuple[float, float, float], ...]:
        if self.locked or np.ptp(self.context.theta_m) < 4 * np.pi:
            return ()
        p = self.params
        w = self.context.speed
        moving = np.abs(w) > 0.3 * float(np.quantile(np.abs(w), 0.9))
        if self.inverse:  # the controller supplies the friction: it is in the current
            y = p.motor.torque_constant * self.ratio * self.context.current * np.sign(w)
            return self._harmonics(y, RIPPLE_ORDERS, moving)
        j_out = p.motor.inertia * self.ratio**2 + p.load.inertia
        acc = np.gradient(w, self.dt) / self.ratio
        # friction level ripple F(theta): J alpha = T - F sgn(w)  ->  F ripple = -J alpha sgn(w)
        y = -j_out * acc * np.sign(w)
        return self._harmonics(y, RIPPLE_ORDERS, moving)

