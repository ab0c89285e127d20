"""Multiple shooting: where a simulated segment restarts, and from which state.

A free-output record is simulated in segments (:meth:`.problem.Problem.predict`); at each
segment's end the model is brought back to the record. :class:`Restarts` (a part of
:class:`.problem.Problem`) finds the pauses (no encoder count for :data:`REST_PAUSE`) and
builds the restart state: while the joint moves, the model's own state with only its slow
drift from the measured motor angle removed (:func:`drift_restart`); at rest, the
measured state, with the measured held torque where a torque sensor has one and the model
can hold it.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from hdgym.effects import BIT, flags_of
from hdgym.params import JointParams
from hdgym.physics import kernel
from hdgym.physics import layout as L
from hdgym.record import Record

from . import residuals as R

REST_PAUSE = 0.03
"""Seconds without an encoder count that make a pause (a restart point, see :class:`Problem`)."""
HOLD_TOL = 1e-6
"""Relative change of the measured held torque beyond which the model cannot hold it at a
rest point (:func:`holdable` had to clip it) and is not restarted at rest there."""
REST_MARGIN = 0.015
"""The restart point lies this long after the pause's first count-free sample (a stopping
joint may creep for a few ms within one count)."""


def pauses(angle: np.ndarray, m: int) -> np.ndarray:
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


def holdable(torque: float, t_motor: float, t_load: float, gear: float, row: np.ndarray,
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


def hysteresis_torque(torsion: float, x: np.ndarray, row: np.ndarray, flags: int) -> float:
    """The hysteresis torque, N m, the kernel's next step gives at ``torsion`` (output rad)
    from sim state ``x`` when the torsion is placed there (``x[DTH]`` set to it, so no
    reversal is seen).

    A Maxwell-slip element keeps its force when the torsion is placed (it moves only with
    the increment from the placed torsion), so that torque is fixed; the tanh element
    (Seyfferth eq. 4) is a function of the torsion since the last reversal, so placing the
    torsion moves its torque too, with a slope of up to 2 gamma B_f just after a reversal
    (on seyfferth-rh32 about 1.7 times the spring's): :func:`hdgym.physics.kernel.step`'s
    formula, evaluated here (tied to the kernel by a test).
    """
    if not flags & BIT["hysteresis"]:
        return 0.0
    if row[L.HMODEL] != 1.0:
        return float(np.sum(x[L.HZ:L.HZ + int(row[L.NSLIP])]))
    s, dts, load = x[L.HZ + 2], x[L.HZ + 1], x[L.HZ + 4]
    gam = row[L.TANH_G] + row[L.TANH_G1] * load
    gam = (1.0 + x[L.HZ + 5]) * gam if gam > 0.0 else 0.0
    return dts + (s * (row[L.TANH_B] + row[L.TANH_B1] * load) - dts) * math.tanh(
        gam * s * (torsion - x[L.HZ]))


def transmitted(torsion: float, x: np.ndarray, row: np.ndarray, flags: int) -> float:
    """The flexspline's torque, N m, at ``torsion`` (output rad) without its damping term:
    the spring's (:func:`hdgym.physics.kernel.spring_torque`) plus the hysteresis torque
    state ``x`` gives there (:func:`hysteresis_torque`); nondecreasing in the torsion."""
    return kernel.spring_torque(torsion, row, flags) + hysteresis_torque(torsion, x, row, flags)


def torsion_for(torque: float, x: np.ndarray, row: np.ndarray, flags: int,
                guess: float) -> float:
    """Torsion (output rad) at which :func:`transmitted` is ``torque`` (bisection, bracketed
    outward from ``guess``, output rad; the hysteresis memory in ``x`` is kept)."""
    step = abs(torque - transmitted(guess, x, row, flags)) / row[L.K1] + 1e-9
    lo, hi = guess - step, guess + step
    while transmitted(lo, x, row, flags) > torque:
        lo -= 2 * (hi - lo)
    while transmitted(hi, x, row, flags) < torque:
        hi += 2 * (hi - lo)
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if transmitted(mid, x, row, flags) < torque:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-12 * max(abs(mid), 1e-12):
            break
    return 0.5 * (lo + hi)


_njit = nb.njit(cache=True, nogil=True)  # a restart's arithmetic runs 10^5 times a diagnosis


@_njit
def ke_at(row: np.ndarray, th: float, on: bool) -> tuple[float, float]:
    """Kinematic error (output rad) and its slope in the WG angle at WG angle ``th``, rad
    (``row``: packed parameters; ``on``: the effect is on)."""
    v = 0.0
    d = 0.0
    if on:
        for j in range(int(row[L.NKE])):
            a = row[L.KE_ORD + j] * th + row[L.KE_PH + j]
            v += row[L.KE_AMP + j] * math.sin(a)
            d += row[L.KE_AMP + j] * row[L.KE_ORD + j] * math.cos(a)
    return v, d


@_njit
def torsion_and_rate(x: np.ndarray, row: np.ndarray, ke_on: bool,
                     ratio: float) -> tuple[float, float]:
    """The torsion (output rad) of sim state ``x`` and its rate (rad/s)."""
    k0, d0 = ke_at(row, x[L.TH_M], ke_on)
    return x[L.TH_M] / ratio - x[L.TH_O] - k0, x[L.W_M] * (1 / ratio - d0) - x[L.W_O]


@_njit
def place_motor(x: np.ndarray, row: np.ndarray, ke_on: bool, ratio: float, angle: float,
                speed: float, tors: float, rate: float) -> None:
    """Put sim state ``x``'s motor at ``angle`` (rad) and ``speed`` (rad/s), in place; the
    output follows so that the torsion is ``tors`` and its rate ``rate``."""
    x[L.TH_M] = angle
    x[L.W_M] = speed
    k1, d1 = ke_at(row, angle, ke_on)
    x[L.TH_O] = angle / ratio - k1 - tors
    x[L.W_O] = speed * (1 / ratio - d1) - rate
    x[L.DTH] = tors


@_njit
def shifted(x: np.ndarray, row: np.ndarray, ke_on: bool, ratio: float, d_angle: float,
            d_speed: float) -> np.ndarray:
    """Sim state ``x`` with the motor angle moved by ``d_angle`` (rad) and the motor speed by
    ``d_speed`` (rad/s), the torsion, its rate and the rest kept (the output follows)."""
    x = x.copy()
    tors, rate = torsion_and_rate(x, row, ke_on, ratio)
    place_motor(x, row, ke_on, ratio, x[L.TH_M] + d_angle, x[L.W_M] + d_speed, tors, rate)
    return x


@_njit
def drift(measured: np.ndarray, model: np.ndarray, dt: float) -> tuple[float, float]:
    """The slow drift of ``model`` from ``measured`` at the end of a window.

    Both are motor angles, rad, over the window's last half (the last sample is the
    restart point); returns ``(angle offset at the last sample, rad; speed offset,
    rad/s)`` of the straight line fitted to ``measured - model`` (least squares). Over a
    WG turn the lines average out of that fit, so what is removed is the drift, not the
    lines.
    """
    n = measured.size
    if n == 0:
        return 0.0, 0.0
    if n < 2:
        return measured[n - 1] - model[n - 1], 0.0
    mid = 0.5 * (n - 1)
    mean = 0.0
    for k in range(n):
        mean += measured[k] - model[k]
    mean /= n
    num = 0.0
    den = 0.0
    for k in range(n):
        t = k - mid
        num += t * (measured[k] - model[k])
        den += t * t
    slope = num / den
    return mean + slope * mid, slope / dt


@_njit
def motor_drift(part: np.ndarray, a: int, rest_angle: np.ndarray,
                dt: float) -> tuple[float, float]:
    """The slow drift of the model's motor angle from the measured one at the end of
    segment ``part`` (sim states of samples ``a`` .. ``b``, ``b`` last): ``(angle offset,
    rad; speed offset, rad/s)`` of :func:`drift` over the segment's last half, against
    ``rest_angle`` (the measured raw, count-centred motor angle, rad, per sample; ``dt``:
    the sample time, s)."""
    b = a + part.shape[0] - 1
    h = max((b - a) // 2, 2)
    return drift(rest_angle[b - h:b + 1], part[-h - 1:, L.TH_M], dt)


@_njit
def drift_restart(part: np.ndarray, a: int, rest_angle: np.ndarray, cur: np.ndarray,
                  row: np.ndarray, ke_on: bool, ratio: float, dt: float) -> np.ndarray:
    """The sim state at the end of segment ``part`` (states of samples ``a`` .. ``b``, the
    restart point ``b`` last) with only its slow drift from the measured motor angle
    removed: the straight line fitted to the measured (``rest_angle``: raw, count-centred,
    rad per sample) minus the simulated motor angle over the segment's last half
    (:func:`motor_drift`) moves the motor angle and speed (:func:`shifted`). The torsion and
    its rate, the hysteresis memory and the model's own ringing stay, and the current is the
    measured one (``cur``: filtered, A, per sample; empty: the record has none, the model
    keeps its own). ``row``: the model's packed parameters
    (:func:`hdgym.physics.layout.pack`); ``ke_on``: its kinematic error is on; ``ratio``:
    the gear ratio; ``dt``: the sample time, s.

    The torsion is not moved towards a torque sensor's reading: a line fitted to the
    measured minus the model's torque over the segment's end also fits the ringing, and
    its rate, put into the torsion rate, fed the next segment's ringing (the true
    seyfferth-rh32 / viscous_friction, seed 50, left 0.87 % at a 0.1 s horizon with it,
    0.02 % without); on the 54 free-output development cases with a torque sensor
    (hold-out seeds 14, 26, 38 and 50) it lowered the true joint's NMSE on none by a
    clear margin and raised it on several (wave-drive-50 / Stribeck, seed 14: 0.12 %
    against 0.02 % at 0.2 s).

    Restarting on the filtered measured speed instead (what :meth:`Restarts._restart` does
    at rest and on a locked output) drops the ringing above the filter's cutoff that the
    model's torsion rate still carries: each restart then injects a speed error, and the
    true joint itself left up to 11 % on the hold-out cases (tuttle-joint1 /
    amplifier_saturation, seed 14: 7.3 % at a 0.1 s horizon, 0.003 % with this restart;
    tuttle-joint3 with nothing hidden: 3.3 %, 1.3 % with the motor's drift removed; both
    measured on the earlier validation records).
    """
    d_angle, d_speed = motor_drift(part, a, rest_angle, dt)
    x = shifted(part[part.shape[0] - 1], row, ke_on, ratio, d_angle, d_speed)
    if cur.size:
        x[L.CUR] = cur[a + part.shape[0] - 1]
    return x


@_njit
def run_segments(x0: np.ndarray, row: np.ndarray, flags: int, dt_sub: float, n_sub: int,
                 u: np.ndarray, t_ext: np.ndarray, bounds: np.ndarray,
                 rest_angle: np.ndarray, cur: np.ndarray, ke_on: bool, ratio: float,
                 dt: float, st: np.ndarray) -> tuple[int, int]:
    """Segments ``bounds[i]`` .. ``bounds[i + 1]`` run one after another from sim state
    ``x0`` (not changed), each but the first from the :func:`drift_restart` of the one
    before, in one compiled call (the Python loop around ~0.1 s segments cost a fifth of
    a prediction on a 5 s window, ~0.6 of ~3 ms). Row ``k`` of ``st`` takes the state at
    sample ``k`` (``u``, A, and ``t_ext``, N m, per sample; ``dt_sub``, s, and ``n_sub``:
    the kernel's substep); the last segment's end row, ``st[bounds[-1]]`` (when inside the
    record), is the model's own state there, for the caller's restart.

    Returns ``(-1, -1)``, or ``(i, k)`` when segment ``i`` diverged at its step ``k``
    (its states from ``st[bounds[i] + 1]`` on, as :meth:`hdgym.sim.Simulator.states`
    reports them).
    """
    n = u.shape[0]
    m = bounds.shape[0] - 1
    x = x0.copy()
    for i in range(m):
        a, b = bounds[i], bounds[i + 1]
        e = min(b + 1, n)
        st[a] = x
        bad = kernel.run_open_loop(x, row, u[a:e - 1], t_ext[a:e - 1], dt_sub, n_sub, flags,
                                   st[a + 1:e])
        if bad >= 0:
            return i, bad
        if i + 1 < m:
            x = drift_restart(st[a:b + 1], a, rest_angle, cur, row, ke_on, ratio, dt)
    return -1, -1


class Restarts:
    """The multiple-shooting part of :class:`.problem.Problem` (uses its record arrays)."""

    record: Record
    locked: bool
    raw: R.Raw
    names: tuple[str, ...]
    dt: float
    cutoff: float
    ratio: float
    counts: tuple[float, float]
    t_ext: np.ndarray
    u: np.ndarray

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
        # what the compiled segment runs take: the current (empty: none) and the schedules
        self._cur = self.x_cur if self.x_cur is not None else np.empty(0)
        self._schedules: dict[int, list[tuple[np.ndarray, bool]]] = {}
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

    def _restart(self, x: np.ndarray, k: int, p: JointParams, row: np.ndarray,
                 at_rest: bool = False) -> np.ndarray:
        """Sim state ``x`` at sample ``k`` moved onto the measured state: a locked output's
        motor angle and speed (filtered; the counted angle and zero at rest), or a free
        output at a rest point (a moving free output restarts by :func:`drift_restart`).

        At rest the speeds are zero, the motor angle is the counted one and the output
        follows with the simulation's own torsion (and hysteresis memory); with a torque
        sensor, the torsion is the one at which the model holds the measured torque
        (:func:`holdable`, :func:`torsion_for`), and where it cannot hold it the model's
        own state is kept. The current is the measured one. ``row``: ``p`` packed
        (:func:`hdgym.physics.layout.pack`).
        """
        r = self.ratio
        ke_on = "kinematic_error" in p.effects
        if self.x_cur is not None:
            x[L.CUR] = self.x_cur[k]
        if self.locked:  # the output stays clamped: the motor angle and speed alone move
            x[L.TH_M] = self.x_rest_angle[k] if at_rest else self.x_th_m[k]
            x[L.W_M] = 0.0 if at_rest else self.x_w_m[k]
            x[L.DTH] = x[L.TH_M] / r - ke_at(row, x[L.TH_M], ke_on)[0] - x[L.TH_O]
            return x
        if not at_rest:
            raise ValueError("a moving free output restarts by drift_restart")
        own = x.copy()
        # the measured joint is still: exact zero speeds, the counted angle
        tors = torsion_and_rate(x, row, ke_on, r)[0]
        x[L.TH_M] = self.x_rest_angle[k]
        x[L.W_M] = 0.0
        k1, d1 = ke_at(row, x[L.TH_M], ke_on)
        x[L.TH_O] = x[L.TH_M] / r - k1 - tors
        x[L.W_O] = 0.0
        if self.rest_torque is not None:  # and the torque it holds
            flags = flags_of(p.effects)
            t_load = row[L.LOAD_T] + self.t_ext[k] + row[L.GRAV] * math.sin(x[L.TH_O])
            measured = float(self.rest_torque[np.searchsorted(self.rest_points, k)])
            held = holdable(measured, row[L.KT] * x[L.CUR], t_load, 1 / r - d1, row,
                            flags, x[L.TH_M], x[L.TH_O])
            if abs(held - measured) > HOLD_TOL * max(abs(measured), 1e-12):
                # the model cannot stand still there with the measured current and
                # torque (a joint creeping within one encoder count as the current
                # rises looks paused): forcing it to rest would inject the torsion of
                # the clipped torque (on tuttle-joint2, 0.73 N m for a measured 0.015,
                # a transmission-error offset that lasted the whole record); the
                # model's own state is kept instead
                return own
            tors = torsion_for(held, x, row, flags, tors)
            x[L.TH_O] = x[L.TH_M] / r - k1 - tors
        x[L.DTH] = tors
        return x

    def _motor_drift(self, part: np.ndarray, a: int) -> tuple[float, float]:
        """The slow drift of the model's motor angle from the measured one at the end of
        segment ``part`` (states of samples ``a`` .. ``b``, ``b`` last): ``(angle offset,
        rad; speed offset, rad/s)`` of the straight line fitted to the measured (raw,
        count-centred) minus the simulated motor angle over the segment's last half
        (:func:`drift`)."""
        return motor_drift(part, a, self.x_rest_angle, self.dt)

    def _blocks(self, seg: int) -> list[tuple[np.ndarray, bool]]:
        """The record's run in segments of ``seg`` samples, grouped into blocks that
        :func:`run_segments` runs in one call: ``(bounds, at_rest)``, the segments
        ``bounds[i]`` .. ``bounds[i + 1]`` restarting by :func:`drift_restart` between
        them, and the block's end ``bounds[-1]`` restarting by :meth:`_restart` (at rest
        when ``at_rest``), or the record's end.

        A segment ends ``seg`` samples on, or at the next rest point before that
        (:meth:`_rest_points`), never mid-pause, and not within two samples of the end.
        That depends on the record alone, not on the model, so it is worked out once per
        ``seg`` (the search asks for a few horizons; thousands of predictions each).
        """
        if seg in self._schedules:
            return self._schedules[seg]
        n = self.u.size
        rest = self.rest_points
        out, bounds, a = [], [0], 0
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
            bounds.append(b)
            if at_rest or self.locked or b == n:  # a restart the compiled run leaves to us
                out.append((np.asarray(bounds, dtype=np.int64), bool(at_rest)))
                bounds = [b]
            a = b
        self._schedules[seg] = out
        return out
