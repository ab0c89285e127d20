"""Tasks: what an environment asks of the joint (references, rewards, observations).

A task turns the joint's measurements into a normalized observation, and the
true state into a reward and a safety termination. Its per-step part is one
compiled function over a whole batch, so a single env (a batch of one) and
the native vector env run the *same* code and give bit-identical results.

Two tasks:

* :class:`TrackingTask` (``HarmonicDriveJoint-v0``): follow an output
  position reference (steps, sines, slow constant speed, point-to-point).
* :class:`ResonanceTask` (``HarmonicDriveResonance-v0``): accelerate the
  motor to a target speed above the 2x-order resonance trap (docs/physics.md, "The resonance trap")
  with little flexspline torque oscillation.

Per-episode draws (reference shape, target speed) come from each env's own
``numpy.random.Generator``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numba as nb
import numpy as np

from hdgym.physics.layout import CUR, TH_O, TK, W_M

#: every observation is clipped to [-OBS_BOUND, OBS_BOUND] (and NaN -> 0)
OBS_BOUND = 10.0

# indices into the constants row ``c`` shared by both post functions
C_RATIO = 0  # nominal ratio
C_IMAX = 1  # nominal current limit, A
C_TNOM = 2  # torque scale, output N m
C_WNOM = 3  # motor speed scale, rad/s
C_TLIM = 4  # safety: |flexspline torque| above this ends the episode, N m
C_WLIM = 5  # safety: |motor speed| above this ends the episode, rad/s
C_PEN = 6  # penalty on a safety termination
C_SDT = 7  # torque-sensor noise sd, N m
C_SDI = 8  # current noise sd, A
C_HOR = 9  # task horizon, s
C_TASK = 10  # first task-specific constant
N_COMMON = C_TASK
#: envs per task call of the threaded post functions
POST_BLOCK = 64


@nb.njit(cache=True, inline="always")
def _box(v: float) -> float:
    """Finite and inside the observation box (NaN -> 0, +-inf -> bound)."""
    if v != v:
        return 0.0
    if v > OBS_BOUND:
        return OBS_BOUND
    if v < -OBS_BOUND:
        return -OBS_BOUND
    return v


@nb.njit(cache=True, inline="always")
def _unsafe(tk: float, w_m: float, bad: bool, t_lim: float, w_lim: float) -> bool:
    return bad or not (abs(tk) <= t_lim) or not (abs(w_m) <= w_lim)


# ---------------------------------------------------------------- tracking

REFERENCES: tuple[str, ...] = ("step", "sine", "constant_speed", "point_to_point")

# task constants after the common ones
J_REF = C_TASK  # reference scale, output rad
J_ERR = C_TASK + 1  # error scale, output rad
J_WCUR = C_TASK + 2  # weight of the current cost
N_JOINT_CONST = C_TASK + 3
# task parameter row: kind, theta0, a, b, c, d
N_JOINT_PARAMS = 6


@nb.njit(cache=True, inline="always")
def _settle(reward: float, unsafe: bool, fresh: bool, penalty: float) -> tuple[float, bool]:
    """Final (reward, terminated): the safety penalty, no NaN reward, and nothing on the
    step that only autoresets an env (NEXT_STEP mode)."""
    if fresh:
        return 0.0, False
    if unsafe:
        reward -= penalty
    if not math.isfinite(reward):
        reward = -penalty
    return reward, unsafe


@nb.njit(cache=True)
def reference(t: float, p: np.ndarray, i: int) -> tuple[float, float]:
    """Output reference (rad) and its rate (rad/s) at ``t`` for parameter row ``p[i]``.

    Indexed in place: a row view per env costs an atomic reference count
    increment and decrement, more than the arithmetic.
    """
    kind = p[i, 0]
    th0 = p[i, 1]
    if kind == 0.0:  # staircase: 0, a, b, c over four segments of d s
        k = int(t / p[i, 5])
        if k <= 0:
            return th0, 0.0
        return th0 + p[i, 1 + min(k, 3)], 0.0
    if kind == 1.0:  # sine a sin(b t)
        return th0 + p[i, 2] * math.sin(p[i, 3] * t), p[i, 2] * p[i, 3] * math.cos(p[i, 3] * t)
    if kind == 2.0:  # constant speed a from time b
        if t <= p[i, 3]:
            return th0, 0.0
        return th0 + p[i, 2] * (t - p[i, 3]), p[i, 2]
    # point-to-point minimum-jerk move of a rad starting at b, lasting c s
    s = (t - p[i, 3]) / p[i, 4]
    if s <= 0.0:
        return th0, 0.0
    if s >= 1.0:
        return th0 + p[i, 2], 0.0
    s3 = s * s * s
    return (th0 + p[i, 2] * s3 * (10.0 - 15.0 * s + 6.0 * s * s),
            p[i, 2] * 30.0 * s * s * (1.0 - s) * (1.0 - s) / p[i, 4])


@nb.njit(cache=True, nogil=True)
def _track_envs(lo: int, hi: int, xs: np.ndarray, bad: np.ndarray, meas: np.ndarray,
                z: np.ndarray, act: np.ndarray, tp: np.ndarray, steps: np.ndarray,
                fresh: np.ndarray, dt: float, c: np.ndarray, obs: np.ndarray, rew: np.ndarray,
                term: np.ndarray, aux: np.ndarray) -> None:
    """Observation, reward and safety termination of tracking envs ``lo`` to ``hi - 1``.

    Per range, not per env: an inlined per-env call took references on its array
    arguments, two atomic operations per array and env, more than the arithmetic.
    """
    # scales as reciprocals: one division per batch instead of a dozen per env
    inv_rs = 1.0 / c[J_REF]
    inv_ratio = 1.0 / c[C_RATIO]
    inv_ws = 1.0 / c[C_WNOM]
    inv_wo = c[C_RATIO] * inv_ws
    inv_imax = 1.0 / c[C_IMAX]
    inv_err = 1.0 / c[J_ERR]
    for i in range(lo, hi):
        t = steps[i] * dt
        r, rd = reference(t, tp, i)
        th_m = meas[0, i]
        th_o = meas[1, i]
        obs[i, 0] = _box(th_o * inv_rs)
        obs[i, 1] = _box(th_m * inv_ratio * inv_rs)
        obs[i, 2] = _box(math.cos(th_m))
        obs[i, 3] = _box(math.sin(th_m))
        obs[i, 4] = _box(meas[2, i] * inv_ws)
        obs[i, 5] = _box(meas[3, i] * inv_wo)
        obs[i, 6] = _box((meas[4, i] + c[C_SDT] * z[i, 0]) / c[C_TNOM])
        obs[i, 7] = _box((meas[5, i] + c[C_SDI] * z[i, 1]) * inv_imax)
        obs[i, 8] = _box(r * inv_rs)
        obs[i, 9] = _box(rd * inv_wo)
        obs[i, 10] = _box((r - th_o) * inv_err)
        obs[i, 11] = _box(act[i])
        e = r - xs[i, TH_O]
        cur = xs[i, CUR] * inv_imax
        reward = 1.0 / (1.0 + abs(e) * inv_err) - c[J_WCUR] * min(cur * cur, 4.0)
        unsafe = _unsafe(xs[i, TK], xs[i, W_M], bad[i], c[C_TLIM], c[C_WLIM])
        rew[i], term[i] = _settle(reward, unsafe, fresh[i], c[C_PEN])
        aux[i, 0] = r
        aux[i, 1] = e if math.isfinite(e) else 0.0


@nb.njit(cache=True)
def post_tracking(xs: np.ndarray, bad: np.ndarray, meas: np.ndarray, z: np.ndarray,
                  act: np.ndarray, tp: np.ndarray, ts: np.ndarray, steps: np.ndarray,
                  fresh: np.ndarray, dt: float, c: np.ndarray, obs: np.ndarray,
                  rew: np.ndarray, term: np.ndarray, aux: np.ndarray) -> None:
    """Observation, reward and safety termination of the tracking task (batch)."""
    _track_envs(0, xs.shape[0], xs, bad, meas, z, act, tp, steps, fresh, dt, c, obs, rew, term,
                aux)


@nb.njit(cache=True, parallel=True)
def post_tracking_parallel(xs: np.ndarray, bad: np.ndarray, meas: np.ndarray, z: np.ndarray,
                           act: np.ndarray, tp: np.ndarray, ts: np.ndarray, steps: np.ndarray,
                           fresh: np.ndarray, dt: float, c: np.ndarray, obs: np.ndarray,
                           rew: np.ndarray, term: np.ndarray, aux: np.ndarray) -> None:
    """:func:`post_tracking` with the envs spread over the cores (same numbers)."""
    n = xs.shape[0]
    for b in nb.prange((n + POST_BLOCK - 1) // POST_BLOCK):
        _track_envs(b * POST_BLOCK, min(n, (b + 1) * POST_BLOCK), xs, bad, meas, z, act, tp,
                    steps, fresh, dt, c, obs, rew, term, aux)


class TrackingTask:
    """Output position tracking (``HarmonicDriveJoint-v0``).

    Args:
        reference: ``"mixed"`` (one of all kinds, drawn per episode), one of
            :data:`REFERENCES`, or a sequence of them to draw from.
        reference_scale: output rad; references stay within about
            +-0.6 of it, and angles are observed divided by it.
        error_scale: output rad; the tracking reward is
            ``1 / (1 + |e| / error_scale)`` and the error channel is
            ``e / error_scale`` (clipped at +-10).
        current_weight: weight of ``(i / I_max)^2`` in the reward.
        max_speed: output rad/s, cap on the sine's peak speed.
    """

    name = "tracking"
    obs_names: tuple[str, ...] = (
        "output_angle", "motor_angle_output_referred", "cos_motor_angle", "sin_motor_angle",
        "motor_velocity", "output_velocity", "output_torque", "motor_current", "reference",
        "reference_velocity", "tracking_error", "previous_action",
    )
    aux_names = ("reference", "tracking_error")
    n_params = N_JOINT_PARAMS
    n_state = 1
    post = staticmethod(post_tracking)
    post_parallel = staticmethod(post_tracking_parallel)

    def __init__(self, reference: str | Sequence[str] = "mixed", reference_scale: float = 0.5,
                 error_scale: float = 1e-3, current_weight: float = 0.05,
                 max_speed: float = 1.5) -> None:
        kinds = REFERENCES if reference == "mixed" else (
            (reference,) if isinstance(reference, str) else tuple(reference))
        for k in kinds:
            if k not in REFERENCES:
                raise ValueError(f"reference: unknown reference {k!r}; known references are "
                                 f"mixed, {', '.join(REFERENCES)}")
        if not kinds:
            raise ValueError("reference: give at least one reference kind")
        for name, v in (("reference_scale", reference_scale), ("error_scale", error_scale),
                        ("max_speed", max_speed)):
            if not (v > 0 and math.isfinite(v)):
                raise ValueError(f"{name} must be > 0, got {v!r}")
        if not (current_weight >= 0 and math.isfinite(current_weight)):
            raise ValueError(f"current_weight must be >= 0, got {current_weight!r}")
        self.kinds = tuple(REFERENCES.index(k) for k in kinds)
        self.reference_scale = float(reference_scale)
        self.error_scale = float(error_scale)
        self.current_weight = float(current_weight)
        self.max_speed = float(max_speed)

    def constants(self) -> list[float]:
        return [self.reference_scale, self.error_scale, self.current_weight]

    def draw(self, rng: np.random.Generator, theta0: float, horizon: float) -> np.ndarray:
        """One episode's reference parameters, starting from output angle ``theta0``."""
        p = np.zeros(N_JOINT_PARAMS)
        kind = self.kinds[int(rng.integers(len(self.kinds)))] if len(self.kinds) > 1 \
            else self.kinds[0]
        a = 0.6 * self.reference_scale
        sign = 1.0 if rng.random() < 0.5 else -1.0
        p[0] = kind
        p[1] = theta0
        if kind == 0:  # staircase
            p[2:5] = rng.uniform(-a, a, 3)
            p[5] = horizon / 4.0
        elif kind == 1:  # sine
            amp = rng.uniform(0.05 * a, a)
            w = 2.0 * math.pi * rng.uniform(0.2, 2.0)
            p[2] = sign * amp
            p[3] = min(w, self.max_speed / amp)
        elif kind == 2:  # slow constant speed: kinematic error dominates the error
            p[2] = sign * rng.uniform(0.005, 0.05)
            p[3] = rng.uniform(0.0, 0.1 * horizon)
        else:  # point-to-point
            p[2] = sign * rng.uniform(0.1 * a, a)
            p[3] = rng.uniform(0.025, 0.25) * horizon
            p[4] = rng.uniform(0.15, 0.5) * horizon
        return p


# ---------------------------------------------------------------- resonance

R_WOSC = C_TASK  # weight of the torque-oscillation cost
R_TAU = C_TASK + 1  # time constant of the torque mean, s
R_DEADLINE = C_TASK + 2  # s, the target must be reached by then
R_TOL = C_TASK + 3  # relative speed tolerance of "reached"
R_TAU_W = C_TASK + 4  # s, time constant of the speed filter that judges "reached"
N_RES_CONST = C_TASK + 5

#: relative tolerance of "target reached": the filtered motor speed within 5 % of the target
REACH_TOLERANCE = 0.05
#: s, time constant of the first-order filter on the true motor speed that judges "reached"
#: (the ripple of the trap, ~30 Hz at 8,000 deg/s, must not fake an arrival)
SPEED_FILTER_S = 0.025


@nb.njit(cache=True, nogil=True)
def _resonance_envs(lo: int, hi: int, xs: np.ndarray, bad: np.ndarray, meas: np.ndarray,
                    z: np.ndarray, act: np.ndarray, tp: np.ndarray, ts: np.ndarray,
                    steps: np.ndarray, fresh: np.ndarray, dt: float, c: np.ndarray,
                    obs: np.ndarray, rew: np.ndarray, term: np.ndarray, aux: np.ndarray) -> None:
    """Observation, reward and safety termination of resonance envs ``lo`` to ``hi - 1``.

    ``ts[i, 0]`` and ``ts[i, 1]`` hold the running means (first-order,
    time constant ``c[R_TAU]``) of the true and measured flexspline torque;
    the oscillation is the torque minus its mean. ``ts[i, 2]`` is the
    filtered true motor speed (rad/s), ``ts[i, 3]`` the time the target was
    first reached (s, NaN before), ``ts[i, 4]`` the peak |flexspline
    torque| so far (N m).
    """
    beta = dt / (c[R_TAU] + dt)
    beta_w = dt / (c[R_TAU_W] + dt)
    tn = c[C_TNOM]
    for i in range(lo, hi):
        wt = tp[i, 0]
        t_meas = meas[4, i] + c[C_SDT] * z[i, 0]
        t_true = xs[i, TK]
        w_true = xs[i, W_M]
        t = steps[i] * dt
        if fresh[i] or not math.isfinite(ts[i, 0]):
            ts[i, 0] = t_true if math.isfinite(t_true) else 0.0
            ts[i, 1] = t_meas if math.isfinite(t_meas) else 0.0
        else:
            ts[i, 0] += beta * (t_true - ts[i, 0])
            ts[i, 1] += beta * (t_meas - ts[i, 1])
        if fresh[i]:
            ts[i, 2] = w_true if math.isfinite(w_true) else 0.0
            ts[i, 3] = math.nan
            ts[i, 4] = abs(t_true) if math.isfinite(t_true) else 0.0
        else:
            if math.isfinite(w_true):
                ts[i, 2] += beta_w * (w_true - ts[i, 2])
            if ts[i, 3] != ts[i, 3] and abs(ts[i, 2] - wt) <= c[R_TOL] * wt:
                ts[i, 3] = t
            a_t = abs(t_true)
            if not (a_t <= ts[i, 4]):  # NaN torque counts as over any rating
                ts[i, 4] = a_t if math.isfinite(a_t) else math.inf
        th_m = meas[0, i]
        obs[i, 0] = _box(meas[2, i] / wt)
        obs[i, 1] = _box(meas[3, i] * c[C_RATIO] / wt)
        obs[i, 2] = _box(math.cos(th_m))
        obs[i, 3] = _box(math.sin(th_m))
        obs[i, 4] = _box(t_meas / tn)
        obs[i, 5] = _box((meas[5, i] + c[C_SDI] * z[i, 1]) / c[C_IMAX])
        obs[i, 6] = _box(wt / c[C_WNOM])
        obs[i, 7] = _box((t_meas - ts[i, 1]) / tn)
        obs[i, 8] = _box(act[i])
        obs[i, 9] = min(t / c[C_HOR], 1.0)  # saturates: past the horizon it looks like its end
        speed_err = min(abs(wt - w_true) / wt, 2.0)
        osc = (t_true - ts[i, 0]) / tn
        reward = 1.0 - speed_err - c[R_WOSC] * min(osc * osc, 4.0)
        unsafe = _unsafe(xs[i, TK], xs[i, W_M], bad[i], c[C_TLIM], c[C_WLIM])
        rew[i], term[i] = _settle(reward, unsafe, fresh[i], c[C_PEN])
        aux[i, 0] = wt
        aux[i, 1] = osc * tn if math.isfinite(osc) else 0.0
        # -1: not reached (info stays finite)
        aux[i, 2] = ts[i, 3] if ts[i, 3] == ts[i, 3] else -1.0
        aux[i, 3] = ts[i, 4] if ts[i, 4] < math.inf else 1e30
        aux[i, 4] = 1.0 if (ts[i, 3] <= c[R_DEADLINE] and ts[i, 4] <= c[C_TLIM]) else 0.0


@nb.njit(cache=True)
def post_resonance(xs: np.ndarray, bad: np.ndarray, meas: np.ndarray, z: np.ndarray,
                   act: np.ndarray, tp: np.ndarray, ts: np.ndarray, steps: np.ndarray,
                   fresh: np.ndarray, dt: float, c: np.ndarray, obs: np.ndarray,
                   rew: np.ndarray, term: np.ndarray, aux: np.ndarray) -> None:
    """Observation, reward and safety termination of the resonance task (batch)."""
    _resonance_envs(0, xs.shape[0], xs, bad, meas, z, act, tp, ts, steps, fresh, dt, c, obs,
                    rew, term, aux)


@nb.njit(cache=True, parallel=True)
def post_resonance_parallel(xs: np.ndarray, bad: np.ndarray, meas: np.ndarray, z: np.ndarray,
                            act: np.ndarray, tp: np.ndarray, ts: np.ndarray, steps: np.ndarray,
                            fresh: np.ndarray, dt: float, c: np.ndarray, obs: np.ndarray,
                            rew: np.ndarray, term: np.ndarray, aux: np.ndarray) -> None:
    """:func:`post_resonance` with the envs spread over the cores (same numbers)."""
    n = xs.shape[0]
    for b in nb.prange((n + POST_BLOCK - 1) // POST_BLOCK):
        _resonance_envs(b * POST_BLOCK, min(n, (b + 1) * POST_BLOCK), xs, bad, meas, z, act, tp,
                        ts, steps, fresh, dt, c, obs, rew, term, aux)


class ResonanceTask:
    """Run the motor up to a target speed above the resonance trap, by a deadline.

    Args:
        target_speed: motor (WG) speed, rad/s: a number, or ``(low, high)``
            to draw uniformly per episode. Default 10,000-12,000 deg/s.
        oscillation_weight: weight of ``((T_k - mean T_k) / T_nom)^2``.
        torque_time_constant: s, the running mean that defines the oscillation.
        deadline: s, success needs the target reached by then (default: no
            deadline).

    "Reached": the true motor speed, filtered first-order with
    :data:`SPEED_FILTER_S`, comes within :data:`REACH_TOLERANCE` of the
    target. ``info`` adds ``time_to_target`` (s, -1 until reached),
    ``peak_torque`` (largest |flexspline torque| so far, N m) and
    ``success`` (1.0 when reached by the deadline with the peak within the
    env's ``torque_limit``, else 0.0; final at the episode's end).
    """

    name = "resonance"
    obs_names: tuple[str, ...] = (
        "motor_velocity", "output_velocity", "cos_motor_angle", "sin_motor_angle",
        "output_torque", "motor_current", "target_speed", "torque_oscillation",
        "previous_action", "time",
    )
    aux_names = ("target_speed", "torque_oscillation", "time_to_target", "peak_torque",
                 "success")
    n_params = 1
    n_state = 5
    post = staticmethod(post_resonance)
    post_parallel = staticmethod(post_resonance_parallel)

    def __init__(self, target_speed: float | tuple[float, float] = (
            math.radians(10_000.0), math.radians(12_000.0)),
                 oscillation_weight: float = 1.0, torque_time_constant: float = 0.05,
                 deadline: float = math.inf) -> None:
        lo, hi = (target_speed, target_speed) if np.isscalar(target_speed) else target_speed
        if not (0 < lo <= hi and math.isfinite(hi)):
            raise ValueError(f"target_speed must be > 0 rad/s (or 0 < low <= high), "
                             f"got {target_speed!r}")
        if not (oscillation_weight >= 0 and math.isfinite(oscillation_weight)):
            raise ValueError(f"oscillation_weight must be >= 0, got {oscillation_weight!r}")
        if not (torque_time_constant > 0 and math.isfinite(torque_time_constant)):
            raise ValueError(f"torque_time_constant must be > 0 s, got {torque_time_constant!r}")
        try:
            deadline = float(deadline)
        except (TypeError, ValueError):
            raise ValueError(f"deadline must be a number of s, got {deadline!r}") from None
        if not deadline > 0:
            raise ValueError(f"deadline must be > 0 s, got {deadline!r}")
        self.target = (float(lo), float(hi))
        self.oscillation_weight = float(oscillation_weight)
        self.torque_time_constant = float(torque_time_constant)
        self.deadline = deadline

    def constants(self) -> list[float]:
        return [self.oscillation_weight, self.torque_time_constant, self.deadline,
                REACH_TOLERANCE, SPEED_FILTER_S]

    def draw(self, rng: np.random.Generator, theta0: float, horizon: float) -> np.ndarray:
        lo, hi = self.target
        return np.array([rng.uniform(lo, hi) if hi > lo else lo])
