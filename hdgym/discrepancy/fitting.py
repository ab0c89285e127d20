"""Fit a joint model to a record: bounded ``scipy.optimize.least_squares`` over dotted paths.

Two ways to compare a model with a record (:class:`Problem`):

``simulate`` (output error, the default)
    re-simulate the record's ``current_command`` and ``load_torque`` with
    :class:`hdgym.sim.Simulator` (true states, ``sensors=False``), quantize
    the simulated angles with the drive's encoder resolution, and compare
    the filtered channels the record has (:mod:`.residuals`).
``inverse`` (equation error, for closed-loop records)
    a record taken under a position controller cannot be re-simulated from
    its current alone (a tiny friction error makes the open-loop position
    drift away); instead the measured motion is pushed through the model's
    rigid-joint inverse dynamics (inertia, friction of both sides with the
    simulator's own friction functions) and the predicted current is
    compared with the measured one while the joint moves.

Residuals are scaled so that the least-squares cost is the sum over
channels of NMSE/100; the NMSE reported is the mean over channels.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba as nb
import numpy as np
from scipy.optimize import least_squares

from hdgym.effects import BIT, flags_of
from hdgym.params import Integration, JointParams
from hdgym.physics import kernel
from hdgym.physics import layout as L
from hdgym.record import Record
from hdgym.sim import SimulationError, Simulator

from . import residuals as R
from .registry import FitParam, Scales, set_values

_BAD = 10.0  # residual per sample (in channel sigmas) of a run that diverged
REST_PAUSE = 0.03
"""Seconds without an encoder count that make a pause (a restart point, see :class:`Problem`)."""
REST_MARGIN = 0.015
"""The restart point lies this long after the pause's first count-free sample (a stopping
joint may creep for a few ms within one count)."""


def with_sample_time(p: JointParams, dt: float) -> JointParams:
    """``p`` with ``ctrl_dt = dt``, keeping the physics substep no longer than before."""
    if abs(p.integration.ctrl_dt - dt) <= 1e-9 * dt:
        return p
    sub = p.integration.dt
    n = max(1, math.ceil(dt / sub - 1e-9))
    return p.set("integration", Integration(ctrl_dt=dt, n_substeps=n))


@nb.njit(cache=True)
def _inverse_friction(p, flags, w_m, th_m, th_o, w_o, t_k, mu, out_in, out_out):  # pragma: no cover
    for k in range(w_m.shape[0]):
        lvl = kernel._friction_level(p, L.FIN, w_m[k], th_m[k], th_o[k], 0.0, flags)
        vis = kernel._viscous_coeff(p, L.FIN, w_m[k], flags)
        out_in[k] = lvl * math.copysign(1.0, w_m[k]) + vis * w_m[k]
        lvl = kernel._friction_level(p, L.FOUT, w_o[k], th_m[k], th_o[k], mu * abs(t_k[k]), flags)
        vis = kernel._viscous_coeff(p, L.FOUT, w_o[k], flags)
        out_out[k] = lvl * math.copysign(1.0, w_o[k]) + vis * w_o[k]


def _pauses(angle: np.ndarray, m: int) -> np.ndarray:
    """Samples inside a run of at least ``m`` + 1 samples with the same encoder count."""
    same = np.diff(angle) == 0
    out = np.zeros(angle.size, dtype=bool)
    run = 0
    for k, s in enumerate(np.append(same, False)):
        if s:
            run += 1
            continue
        if run >= m:
            out[k - run:k + 1] = True
        run = 0
    return out


def _holdable(torque: float, t_motor: float, t_load: float, gear: float, row: np.ndarray,
              flags: int, th_m: float, th_o: float) -> float:
    """The transmitted torque nearest ``torque`` at which the model can stand still.

    At rest the output friction must hold ``torque - t_load`` and the motor
    friction ``t_motor - gear torque``, each within its static level (the
    model's own, at this angle). A measured held torque the model cannot hold is
    clipped to what it can (when the two sides allow no common torque, to what the
    output side can hold and the motor slips), so a restart never starts the model
    with a slip it could not have reached (the cost stays continuous in the static
    levels) while the torque it fails to hold still shows in the residual.
    """
    mu = row[L.MU_LOAD] if flags & BIT["load_dependent_friction"] else 0.0
    l_out = kernel._friction_level(row, L.FOUT, 0.0, th_m, th_o, mu * abs(torque), flags)
    l_in = kernel._friction_level(row, L.FIN, 0.0, th_m, th_o, 0.0, flags)
    lo, hi = t_load - l_out, t_load + l_out
    if gear > 0:
        lo_m, hi_m = (t_motor - l_in) / gear, (t_motor + l_in) / gear
        if max(lo, lo_m) <= min(hi, hi_m):
            lo, hi = max(lo, lo_m), min(hi, hi_m)
    return min(max(torque, lo), hi)


def _held_torsion(torque: float, x: np.ndarray, row: np.ndarray, flags: int) -> float:
    """Torsion (output rad) at which the model's flexspline holds ``torque`` at rest.

    The hysteresis memory in ``x`` is kept; the spring takes the rest (the spring
    torque is monotonic in the torsion, so bisection finds it).
    """
    t_h = 0.0
    if flags & BIT["hysteresis"]:
        t_h = (x[L.HZ + 3] if row[L.HMODEL] == 1.0
               else float(np.sum(x[L.HZ:L.HZ + int(row[L.NSLIP])])))
    target = torque - t_h
    x0 = target / row[L.K1]
    lo, hi = x0 - abs(x0) - 1e-9, x0 + abs(x0) + 1e-9
    while kernel.spring_torque(lo, row, flags) > target:
        lo -= 2 * (hi - lo)
    while kernel.spring_torque(hi, row, flags) < target:
        hi += 2 * (hi - lo)
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if kernel.spring_torque(mid, row, flags) < target:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-12 * max(abs(mid), 1e-12):
            break
    return 0.5 * (lo + hi)


@dataclass
class Problem:
    """A record prepared for comparison with models.

    Args:
        record: the measured (or simulated) record.
        params: the drive (sets ratio, encoders and sample time).
        mode: ``"simulate"``, ``"inverse"`` or ``"auto"`` (inverse when the
            record's metadata says ``loop: closed`` or it has no
            ``current_command``).
        cutoff: filter cutoff, Hz (default :func:`residuals.default_cutoff`).
        channels: compare exactly these channels (a validation record uses
            the training record's), default: what the record supports.
        segment: free-output records are simulated in segments of this many
            seconds, each restarted from the measured angles, speeds and
            current (multiple shooting), so a small speed error cannot grow
            into a position drift that scrambles position-periodic effects
            (0 or None: one run). Restarts happen only while the measured
            joint moves (faster than 10 % of its typical speed), or early in a
            pause in which the measured joint stands still (no encoder count
            for :data:`REST_PAUSE`; restarted at zero speed and, with a torque
            sensor, at the measured held torque), so sticking and breakaway stay
            the model's own.
    """

    record: Record
    params: JointParams
    mode: str = "auto"
    cutoff: float | None = None
    channels: tuple[str, ...] | None = None
    segment: float = 0.5
    names: tuple[str, ...] = field(init=False)
    measured: dict[str, np.ndarray] = field(init=False)
    sigma2: dict[str, float] = field(init=False)
    context: R.Context = field(init=False)
    scales: Scales = field(init=False)
    mask: np.ndarray | None = field(init=False, default=None)

    def __post_init__(self) -> None:
        rec = self.record
        self.dt = float(rec.dt)
        self.cutoff = self.cutoff or R.default_cutoff(self.dt)
        self.locked = rec.locked_output
        self.ratio = float(rec.ratio or self.params.ratio)
        if self.mode == "auto":
            closed = rec.meta.get("loop", "") == "closed" or not rec.has("current_command")
            self.mode = "inverse" if closed else "simulate"
        if self.mode not in ("simulate", "inverse"):
            raise ValueError(f"mode must be simulate, inverse or auto, got {self.mode!r}")
        self.inverse = self.mode == "inverse"
        if self.inverse and (not rec.has("motor_current") or rec.output_angle is None):
            raise ValueError(f"{rec.source}: the inverse comparison needs motor_current and "
                             f"output_angle columns")
        if not self.inverse and not rec.has("current_command"):
            raise ValueError(f"{rec.source}: no column 'current_command' to simulate")
        s = self.params.sensors
        self.counts = (float(s.motor_counts), float(s.output_counts))
        self.u = (np.asarray(rec.current_command, dtype=float) if rec.has("current_command")
                  else np.asarray(rec.motor_current, dtype=float))
        tl = rec.load_torque  # external load applied on top of the model's own load
        self.t_ext = np.zeros(len(rec)) if tl is None else np.asarray(tl, dtype=float).copy()
        raw = R.Raw(motor_angle=np.asarray(rec.motor_angle, dtype=float),
                    output_angle=None if self.locked else rec.output_angle,
                    output_torque=rec.output_torque, motor_current=rec.motor_current)
        self.raw = raw
        self.names = R.pick_channels(raw, self.locked, self.ratio, self.dt, self.cutoff,
                                     *self.counts, inverse=self.inverse)
        if self.channels is not None:
            missing = [c for c in self.channels if c not in R.CHANNEL_UNITS]
            if missing:
                raise ValueError(f"unknown channel(s) {missing}")
            self.names = tuple(self.channels)
        self.measured = R.channels(raw, self.names, self.ratio, self.dt, self.cutoff)
        if self.inverse:
            self._prepare_inverse()
        else:
            self._prepare_shooting()
        self.sigma2 = {k: max(float(np.var(self._m(v))), 1e-300)
                       for k, v in self.measured.items()}
        self.context = self._context()
        self.scales = self._scales()

    # -- helpers

    def _m(self, x: np.ndarray) -> np.ndarray:
        return x if self.mask is None else x[self.mask]

    stick_slip: bool = field(init=False, default=False)
    """Whether the joint stops and sticks in the record (restarts at rest; see
    :func:`fit`'s ``search``)."""

    def _prepare_inverse(self) -> None:
        th_o = lowpass_ = R.lowpass(self.raw.output_angle, self.dt, self.cutoff)
        self.th_o = lowpass_
        self.w_o = np.gradient(th_o, self.dt)
        self.a_o = np.gradient(self.w_o, self.dt)
        self.th_m = R.lowpass(self.raw.motor_angle, self.dt, self.cutoff)
        self.w_m = np.gradient(self.th_m, self.dt)
        vmax = float(np.quantile(np.abs(self.w_o), 0.95))
        self.mask = np.abs(self.w_o) > 0.2 * vmax

    def _context(self) -> R.Context:
        raw = self.raw
        th_m = R.lowpass(raw.motor_angle, self.dt, self.cutoff)
        speed = np.gradient(th_m, self.dt)
        torsion = None
        if self.locked:
            torsion = th_m / self.ratio
        elif raw.output_angle is not None and "transmission_error" in self.names:
            torsion = th_m / self.ratio - R.lowpass(raw.output_angle, self.dt, self.cutoff)
        current = raw.motor_current if raw.motor_current is not None else self.u
        current = R.lowpass(current, self.dt, self.cutoff)
        if raw.output_torque is not None:
            torque = R.lowpass(raw.output_torque, self.dt, self.cutoff)
        else:
            torque = self.params.motor.torque_constant * self.ratio * current
        return R.Context(time=np.asarray(self.record.time), theta_m=th_m, speed=speed,
                         torsion=torsion, torque=torque, current=current, dt=self.dt,
                         cutoff=self.cutoff, held=self._held(speed))

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
        motor_stuck = _pauses(np.asarray(raw.motor_angle, dtype=float), m)
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
            out_stuck = (_pauses(th_o, m) if raw.output_angle is not None else motor_stuck)
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
        cm = float(np.max(np.abs(self.raw.motor_current))) if self.raw.motor_current is not None \
            else 0.0
        i_for_v = self.raw.motor_current if self.raw.motor_current is not None else self.u
        volt = float(np.max(np.abs(p.motor.resistance * i_for_v
                                   + p.motor.back_emf_constant * c.speed)))
        te = float(np.std(self.measured["transmission_error"])) \
            if "transmission_error" in self.measured else 0.0
        static = tuple((side, *lv) for side, h in c.held.items()
                       if (lv := R.friction_levels(h, self.dt, self.cutoff)) is not None)
        return Scales(torque=torque, speed=speed, torsion=torsion, current=cur,
                      current_measured=cm, voltage=volt, locked=self.locked,
                      inverse=self.inverse, transmission_error=te, ke=self._ke_guess(),
                      ripple=self._ripple_guess(), static=static)

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
        from .registry import ke_lines

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
        from .registry import RIPPLE_ORDERS

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

    def masked_context(self) -> R.Context:
        """The context restricted to the compared samples (all of them in simulate mode)."""
        c, m = self.context, self.mask
        if m is None:
            return c
        return R.Context(time=c.time[m], theta_m=c.theta_m[m], speed=c.speed[m],
                         torsion=None if c.torsion is None else c.torsion[m],
                         torque=None if c.torque is None else c.torque[m],
                         current=c.current[m], dt=c.dt, cutoff=c.cutoff)

    def _prepare_shooting(self) -> None:
        """Measured states to restart simulation segments from (filtered, de-biased)."""
        mc, oc = self.counts
        qm = 2 * math.pi / mc if mc else 0.0
        self.x_th_m = R.lowpass(self.raw.motor_angle, self.dt, self.cutoff) + qm / 2
        self.x_w_m = np.gradient(self.x_th_m, self.dt)
        typical = float(np.quantile(np.abs(self.x_w_m), 0.9))
        self.x_moving = np.abs(self.x_w_m) > 0.1 * typical
        self.x_cur = (R.lowpass(self.raw.motor_current, self.dt, self.cutoff)
                      if self.raw.motor_current is not None else None)
        self.x_rest_angle = np.asarray(self.raw.motor_angle, dtype=float) + qm / 2
        self.rest_points = self._rest_points()
        self.stick_slip = bool(self.rest_points.size)

    def _rest_points(self) -> np.ndarray:
        """Samples shortly after the measured joint has come to rest.

        A pause is :data:`REST_PAUSE` seconds or more in which no encoder count
        changes; the restart point lies :data:`REST_MARGIN` after its start. There
        the measured state is exact (speeds zero, angles known to a count), so a
        segment can restart from it without injecting a speed error, while the
        rest of the pause and the breakaway that ends it stay the model's own (a
        model that breaks away too early or too late shows it). With a torque sensor
        the torque the stuck joint holds is known too (``rest_torque``, its mean over
        the pause), so the restart also takes the measured torsion: a stop whose held
        torque the model got wrong (it depends on the phase of the ringing at the
        stop) does not carry into the next breakaway, and each breakaway is compared
        from the measured state, event by event.
        """
        m = int(round(REST_PAUSE / self.dt))
        margin = int(round(REST_MARGIN / self.dt))
        still = np.diff(self.raw.motor_angle) == 0
        if self.raw.output_angle is not None:
            still &= np.diff(np.asarray(self.raw.output_angle, dtype=float)) == 0
        torque = (np.asarray(self.raw.output_torque, dtype=float)
                  if "output_torque" in self.names else None)
        out, held = [], []
        run = 0
        for k, s in enumerate(np.append(still, False)):  # still[k]: no count from k to k+1
            if s:
                run += 1
                continue
            if run >= m:
                out.append(k - run + margin)
                if torque is not None:  # samples k - run .. k share their counts
                    held.append(float(np.mean(torque[k - run:k + 1])))
            run = 0
        self.rest_torque = np.asarray(held) if torque is not None else None
        return np.asarray(out, dtype=int)

    def _restart(self, x: np.ndarray, k: int, p: JointParams, at_rest: bool = False
                 ) -> np.ndarray:
        """Sim state ``x`` at sample ``k`` moved onto the measured motor angle, speed, current.

        The output follows with the simulation's own torsion and torsion rate (and
        hysteresis memory), so a restart injects no torque: only the drift of the
        motor angle is removed. At rest with a torque sensor, the torsion is the one
        at which the model holds the measured torque (:func:`_holdable`,
        :func:`_held_torsion`).
        """
        r = self.ratio
        row = L.pack(p)
        ke_on = "kinematic_error" in p.effects

        def ke(th: float) -> tuple[float, float]:
            if not ke_on:
                return 0.0, 0.0
            v = d = 0.0
            for j in range(int(row[L.NKE])):
                a = row[L.KE_ORD + j] * th + row[L.KE_PH + j]
                v += row[L.KE_AMP + j] * math.sin(a)
                d += row[L.KE_AMP + j] * row[L.KE_ORD + j] * math.cos(a)
            return v, d

        k0, d0 = ke(x[L.TH_M])
        tors = x[L.TH_M] / r - x[L.TH_O] - k0
        rate = x[L.W_M] * (1 / r - d0) - x[L.W_O]
        if self.x_cur is not None:
            x[L.CUR] = self.x_cur[k]
        if at_rest:  # the measured joint is still: exact zero speeds, the counted angle
            x[L.TH_M] = self.x_rest_angle[k]
            x[L.W_M] = 0.0
            k1, d1 = ke(x[L.TH_M])
            x[L.TH_O] = x[L.TH_M] / r - k1 - tors
            x[L.W_O] = 0.0
            if self.rest_torque is not None:  # and the torque it holds
                flags = flags_of(p.effects)
                t_load = row[L.LOAD_T] + self.t_ext[k] + row[L.GRAV] * math.sin(x[L.TH_O])
                held = _holdable(float(self.rest_torque[np.searchsorted(self.rest_points, k)]),
                                 row[L.KT] * x[L.CUR], t_load, 1 / r - d1, row, flags,
                                 x[L.TH_M], x[L.TH_O])
                tors = _held_torsion(held, x, row, flags)
                x[L.TH_O] = x[L.TH_M] / r - k1 - tors
        else:
            x[L.TH_M] = self.x_th_m[k]
            x[L.W_M] = self.x_w_m[k]
            k1, d1 = ke(x[L.TH_M])
            x[L.TH_O] = x[L.TH_M] / r - k1 - tors
            x[L.W_O] = x[L.W_M] * (1 / r - d1) - rate
        x[L.DTH] = tors
        return x

    # -- model output

    def predict(self, p: JointParams) -> dict[str, np.ndarray]:
        """The model's filtered channels for this record (raises SimulationError)."""
        if self.inverse:
            return {"motor_current": self._inverse(p)}
        p = with_sample_time(p, self.dt)
        sim = Simulator(p, locked_output=self.locked, sensors=False)
        x0 = sim.initial_state(float(self.raw.motor_angle[0]))
        n = self.u.size
        seg = n if (self.locked or not self.segment) else max(int(round(self.segment / self.dt)), 2)
        if seg >= n:
            _, _, _, st = sim.trajectory(self.u, load_torque=self.t_ext, state=x0)
        else:
            st = np.empty((n, L.N_STATE))
            a = 0
            rest = self.rest_points
            # a restart at rest may move a model that is still running back onto the measured
            # angle; the compared channels follow the model's own (continuous) angle, so the
            # jump does not show as a spike in the differentiated speed
            jump = np.zeros(2)
            while a < n:
                b = min(a + seg, n)
                j = int(np.searchsorted(rest, a, side="right"))
                at_rest = j < rest.size and rest[j] <= b
                if at_rest:  # a pause starts before the segment would end: restart at rest
                    b = int(rest[j])
                else:
                    while b < n and not self.x_moving[b]:  # never restart a joint mid-pause
                        b += 1
                if n - b < 2:
                    b, at_rest = n, False
                e = min(b + 1, n)
                _, _, _, part = sim.trajectory(self.u[a:e], load_torque=self.t_ext[a:e], state=x0)
                st[a:b] = part[: b - a]
                st[a:b, L.TH_M] -= jump[0]
                st[a:b, L.TH_O] -= jump[1]
                if b < n:
                    x0 = self._restart(part[b - a].copy(), b, p, at_rest)
                    if at_rest:
                        jump[0] += x0[L.TH_M] - part[b - a, L.TH_M]
                        jump[1] += x0[L.TH_O] - part[b - a, L.TH_O]
                a = b
        mc, oc = self.counts
        raw = R.Raw(motor_angle=R.quantize(st[:, L.TH_M], mc),
                    output_angle=None if self.locked else R.quantize(st[:, L.TH_O], oc),
                    output_torque=st[:, L.TK], motor_current=st[:, L.CUR])
        return R.channels(raw, self.names, self.ratio, self.dt, self.cutoff)

    def _inverse(self, p: JointParams) -> np.ndarray:
        """Predicted current from the measured motion (rigid joint, no measured torque used)."""
        row = L.pack(p)
        flags = flags_of(p.effects)
        r = self.ratio
        n = self.w_o.size
        f_in, f_out = np.empty(n), np.empty(n)
        kt = p.motor.torque_constant
        load = p.load
        t_load = load.torque + load.gravity * np.sin(self.th_o) + self.t_ext
        mu = row[L.MU_LOAD] if "load_dependent_friction" in p.effects else 0.0
        # transmitted torque T_k = J_o a + T_load + F_out(T_k): two fixed-point passes
        t_k = load.inertia * self.a_o + t_load
        for _ in range(2 if mu > 0 else 1):
            _inverse_friction(row, flags, self.w_m, self.th_m, self.th_o, self.w_o, t_k, mu,
                              f_in, f_out)
            t_k = load.inertia * self.a_o + t_load + f_out
        t_m = p.motor.inertia * r * self.a_o + t_k / r + f_in
        return R.lowpass(t_m / kt, self.dt, self.cutoff)

    def residuals(self, p: JointParams) -> dict[str, np.ndarray]:
        """Model minus measurement, per channel (masked samples dropped in inverse mode)."""
        pred = self.predict(p)
        return {k: self._m(pred[k] - self.measured[k]) for k in self.names}

    def nmse(self, p: JointParams) -> dict[str, float]:
        """NMSE% per channel and ``"mean"`` over channels (inf if the run diverged)."""
        try:
            res = self.residuals(p)
        except SimulationError:
            return {**{k: math.inf for k in self.names}, "mean": math.inf}
        out = {k: 100.0 * float(np.mean(r**2)) / self.sigma2[k] for k, r in res.items()}
        out["mean"] = float(np.mean(list(out.values())))
        return out

    def vector(self, p: JointParams, decimate: int = 1) -> np.ndarray:
        """Stacked scaled residuals; ``0.5 |v|^2 = 0.5 sum NMSE/100``."""
        try:
            res = self.residuals(p)
        except (SimulationError, FloatingPointError):
            n = sum(self._m(self.measured[k])[::decimate].size for k in self.names)
            return np.full(n, _BAD)
        parts = []
        for k, r in res.items():
            r = r[::decimate]
            parts.append(r / math.sqrt(self.sigma2[k] * r.size))
        v = np.concatenate(parts)
        return np.where(np.isfinite(v), v, _BAD)


@dataclass
class FitResult:
    """Outcome of :func:`fit`: the fitted joint, fitted values and NMSE per channel."""

    params: JointParams
    values: dict[str, float]
    nmse: dict[str, float]
    nfev: int
    cost: float


DIFF_STEP = 1e-3
"""Finite-difference step, as a share of each parameter's range (stick-slip makes the cost
rough on a finer scale)."""


def fit(problem: Problem, p: JointParams, fps: list[FitParam], max_nfev: int = 40,
        decimate: int | None = None, diff_step: float | None = None,
        search: bool = False) -> FitResult:
    """Bounded least squares of ``fps`` (starting at their guesses or current values).

    Variables are scaled to their bounds (``z = 1 + (x - lo)/(hi - lo)``) so
    a relative finite-difference step (:data:`DIFF_STEP`) is that share of each range.
    With ``search`` on a stick-slip record (:attr:`Problem.stick_slip`), a
    coordinate search (:func:`_pattern_search`) continues from the least-squares
    result.
    """
    from .registry import get_value

    if decimate is None:
        decimate = max(1, problem.measured[problem.names[0]].size // 8000)
    fps = [fp for fp in fps if fp.upper > fp.lower]
    if not fps:
        nm = problem.nmse(p)
        return FitResult(p, {}, nm, 0, nm["mean"] / 100)
    lo = np.array([fp.lower for fp in fps])
    hi = np.array([fp.upper for fp in fps])
    x0 = np.array([fp.guess if fp.guess is not None else get_value(p, fp.path) for fp in fps])
    x0 = np.clip(x0, lo, hi)
    span = hi - lo

    def build(z: np.ndarray) -> JointParams:
        x = lo + (np.clip(z, 1.0, 2.0) - 1.0) * span
        return set_values(p, {fp.path: float(v) for fp, v in zip(fps, x, strict=True)})

    def fun(z: np.ndarray) -> np.ndarray:
        try:
            q = build(z)
        except ValueError:
            n = problem.vector(p, decimate).size
            return np.full(n, _BAD)
        return problem.vector(q, decimate)

    z0 = 1.0 + (x0 - lo) / span
    sol = least_squares(fun, z0, bounds=(np.ones_like(z0), 2 * np.ones_like(z0)), method="trf",
                        diff_step=diff_step or DIFF_STEP, max_nfev=max_nfev, ftol=1e-6,
                        xtol=1e-6, gtol=1e-8)
    z, nfev = sol.x, int(sol.nfev)
    if search and problem.stick_slip:
        z, n = _pattern_search(lambda v: float(np.sum(fun(v) ** 2)), np.clip(z, 1.0, 2.0),
                               SEARCH_BUDGET * len(fps))
        nfev += n
    best = build(z)
    values = {fp.path: float(get_value(best, fp.path)) for fp in fps}
    nm = problem.nmse(best)
    return FitResult(best, values, nm, nfev, nm["mean"] / 100)


SEARCH_STEPS = (0.04, 0.02, 0.01, 0.005)
"""Coordinate-search steps, as shares of each parameter's range (:func:`_pattern_search`)."""
SEARCH_BUDGET = 30
"""Cost evaluations per parameter a coordinate search may spend."""


def _pattern_search(cost, z: np.ndarray, budget: int) -> tuple[np.ndarray, int]:
    """Bounded coordinate search on ``z`` in ``[1, 2]`` (steps :data:`SEARCH_STEPS`).

    Stick-slip makes the cost piecewise constant on a fine scale (each breakaway
    and slip happens at a whole substep, the simulated angles are quantized like
    the encoders), so a finite-difference Jacobian sees steps rather than a slope
    and least squares stops early; comparing costs a few per cent of each range
    apart follows the trend. Returns the best point and the evaluations spent.
    """
    best = cost(z)
    n = 1
    for step in SEARCH_STEPS:
        improved = True
        while improved and n < budget:
            improved = False
            for i in range(z.size):
                for sgn in (1.0, -1.0):
                    y = z.copy()
                    y[i] = min(max(z[i] + sgn * step, 1.0), 2.0)
                    if y[i] == z[i]:
                        continue
                    c = cost(y)
                    n += 1
                    if c < best:
                        best, z, improved = c, y, True
                        break
                if n >= budget:
                    break
    return z, n
