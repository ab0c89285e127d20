"""The compiled joint step (numba).

One substep is semi-implicit (symplectic) Euler on the two-inertia joint:

1. torsion ``dth = th_m/r - th_o - ke(th_m)`` and the transmitted torque
   ``T_k = spring(dth) + c d(dth)/dt + T_h`` (hysteresis memory updated with
   the torsion increment since the last substep);
2. amplifier: clip, back-EMF voltage limit, first-order current loop
   (exact discretisation, so any bandwidth is stable);
3. speeds: the motor sees ``T_m - T_k (1/r - ke'(th_m))`` (power balance
   through the kinematic-error element, Tuttle model 4), the output
   ``T_k - T_load``; viscous friction is implicit, Coulomb friction is an
   impulse bounded by its level so speeds stop exactly at zero and stick
   (no chattering, unconditionally stable);
4. angles from the new speeds.

Energy bookkeeping (dissipated energy, motor and load work) rides in the
state so tests can close the energy balance. The plain-numpy twin of this
step is :mod:`hdgym.physics.reference`.
"""

from __future__ import annotations

import math
import os

import numba as nb
import numpy as np

from hdgym.effects import BIT, LOCKED_OUTPUT_BIT
from hdgym.physics.layout import (
    BW,
    CDAMP,
    CMODEL,
    CUR,
    DTH,
    E_DISS,
    F_B1,
    F_B2,
    F_FC,
    F_FS,
    F_NRIP,
    F_RAMP,
    F_RFRAME,
    F_RORD,
    F_RPH,
    F_WS,
    FIN,
    FOUT,
    GRAV,
    HMODEL,
    HZ,
    I_MAX,
    J_M,
    J_O,
    K0,
    K1,
    K3,
    KB,
    KE_AMP,
    KE_ORD,
    KE_PH,
    KNEE,
    KT,
    LOAD_T,
    MU_LOAD,
    N_STATE,
    NKE,
    NSLIP,
    RATIO,
    RES,
    SK2,
    SK3,
    SLIP_K,
    SLIP_W,
    ST1,
    ST2,
    T_LOAD,
    T_MOTOR,
    TANH_B,
    TANH_G,
    TH_M,
    TH_O,
    TK,
    V_MAX,
    W_LOAD,
    W_M,
    W_MOTOR,
    W_O,
)

# Numba's default OpenMP layer busy-waits between parallel regions; on a shared
# machine (or beside torch's own OpenMP threads during RL training) that made
# step_parallel 3-8x slower than one thread. The work-queue layer sleeps
# instead. A layer chosen by the user (NUMBA_THREADING_LAYER) is kept.
if "NUMBA_THREADING_LAYER" not in os.environ:
    nb.config.THREADING_LAYER = "workqueue"

KE = BIT["kinematic_error"]
NONLIN = BIT["nonlinear_stiffness"]
HYST = BIT["hysteresis"]
COUL = BIT["coulomb_friction"]
VISC = BIT["viscous_friction"]
STRIB = BIT["stribeck_friction"]
STICK = BIT["stiction"]
POSDEP = BIT["position_dependent_friction"]
LOADDEP = BIT["load_dependent_friction"]
AMP = BIT["amplifier_saturation"]
LOCKED = LOCKED_OUTPUT_BIT

_jit = nb.njit(cache=True, fastmath=False, nogil=True)


@_jit
def spring_torque(x: float, p: np.ndarray, flags: int) -> float:
    """Spring torque of the flexspline at torsion ``x`` (output rad), N m."""
    k1 = p[K1]
    if not (flags & NONLIN):
        return k1 * x
    model = p[CMODEL]
    if model == 1.0:
        return k1 * x + p[K3] * x * x * x
    if model == 2.0:
        ax = abs(x)
        if ax <= p[KNEE]:
            return k1 * x
        return k1 * x + p[K0] * (ax - p[KNEE]) * math.copysign(1.0, x)
    if model == 3.0:
        ax = abs(x)
        th1 = p[ST1] / k1
        th2 = th1 + (p[ST2] - p[ST1]) / p[SK2]
        if ax <= th1:
            return k1 * x
        s = math.copysign(1.0, x)
        if ax <= th2:
            return s * (p[ST1] + p[SK2] * (ax - th1))
        return s * (p[ST2] + p[SK3] * (ax - th2))
    return k1 * x


@_jit
def _friction_level(p: np.ndarray, base: int, w: float, th_in: float, th_out: float,
                    extra: float, flags: int) -> float:
    """Coulomb-type friction level (>= 0) at speed ``w``; ``w == 0`` means stuck."""
    level = 0.0
    if flags & COUL:
        fc = p[base + F_FC]
        if w == 0.0:
            level = p[base + F_FS] if (flags & (STICK | STRIB)) else fc
        elif flags & STRIB:
            r = w / p[base + F_WS]
            r2 = r * r
            # exp(-40) < 5e-18: skip the call far above the Stribeck speed
            level = fc + (p[base + F_FS] - fc) * math.exp(-r2) if r2 < 40.0 else fc
        else:
            level = fc
    if flags & POSDEP:
        for k in range(int(p[base + F_NRIP])):
            ang = th_in if p[base + F_RFRAME + k] == 0.0 else th_out
            phase = p[base + F_RORD + k] * ang + p[base + F_RPH + k]
            level += p[base + F_RAMP + k] * math.sin(phase)
    level += extra
    return level if level > 0.0 else 0.0


@_jit
def _viscous_coeff(p: np.ndarray, base: int, w: float, flags: int) -> float:
    """Secant viscous coefficient f(w)/w >= 0 of ``b1 w + b2 w^3`` clamped at its peak."""
    if not (flags & VISC):
        return 0.0
    b1 = p[base + F_B1]
    b2 = p[base + F_B2]
    if b2 == 0.0:
        return b1
    if b2 > 0.0:
        return b1 + b2 * w * w
    w2 = w * w
    wpk2 = b1 / (-3.0 * b2)
    if w2 <= wpk2:
        return b1 + b2 * w2
    # beyond the peak the torque stays at f(w_pk)
    wpk = math.sqrt(wpk2)
    return (b1 * wpk + b2 * wpk2 * wpk) / abs(w)


@_jit
def _advance(w: float, tau: float, inertia: float, visc: float, level: float,
             dt: float) -> tuple[float, float]:
    """New speed under torque ``tau``, implicit viscous and bounded Coulomb impulse.

    Returns (new speed, dissipated power).
    """
    denom = 1.0 + dt * visc / inertia
    v_free = (w + dt * tau / inertia) / denom
    dv = dt * level / inertia / denom
    if abs(v_free) <= dv:
        return 0.0, 0.0
    v = v_free - math.copysign(dv, v_free)
    return v, visc * v * v + level * abs(v)


@_jit
def substeps(x: np.ndarray, p: np.ndarray, i_cmd: float, t_ext: float, dt: float,
             n_sub: int, flags: int) -> None:
    """Advance one env's state ``x`` in place by ``n_sub`` substeps of ``dt`` s.

    ``i_cmd`` is the current command (A); ``t_ext`` an external load torque
    (N m, resisting positive output motion) added to the preset's load.
    """
    r = p[RATIO]
    inv_r = 1.0 / r
    jm = p[J_M]
    jo = p[J_O]
    alpha = 1.0 - math.exp(-2.0 * math.pi * p[BW] * dt)
    locked = (flags & LOCKED) != 0
    nke = int(p[NKE]) if (flags & KE) else 0
    nslip = int(p[NSLIP]) if (flags & HYST) else 0
    tanh_model = p[HMODEL] == 1.0 and (flags & HYST) != 0
    mu = p[MU_LOAD] if (flags & LOADDEP) else 0.0
    for _ in range(n_sub):
        th_m = x[TH_M]
        w_m = x[W_M]
        th_o = x[TH_O]
        w_o = x[W_O]
        # --- kinematic error and torsion
        ke = 0.0
        dke = 0.0
        for k in range(nke):
            a = p[KE_ORD + k] * th_m + p[KE_PH + k]
            amp = p[KE_AMP + k]
            ke += amp * math.sin(a)
            dke += amp * p[KE_ORD + k] * math.cos(a)
        dth = th_m * inv_r - th_o - ke
        gear = inv_r - dke
        ddth = w_m * gear - w_o
        d_inc = dth - x[DTH]
        x[DTH] = dth
        # --- hysteresis
        t_h = 0.0
        diss = 0.0
        if tanh_model:
            s = x[HZ + 2]
            if d_inc != 0.0:
                s_new = 1.0 if d_inc > 0.0 else -1.0
                if s_new != s:  # reversal: remember where and how much
                    x[HZ] = dth - d_inc
                    x[HZ + 1] = x[HZ + 3]
                    x[HZ + 2] = s_new
                    s = s_new
            dts = x[HZ + 1]
            t_h = dts + (s * p[TANH_B] - dts) * math.tanh(p[TANH_G] * s * (dth - x[HZ]))
            x[HZ + 3] = t_h
        else:
            for k in range(nslip):
                kap = p[SLIP_K + k]
                wk = p[SLIP_W + k]
                f = x[HZ + k] + kap * d_inc
                if f > wk:
                    if kap > 0.0:
                        diss += wk * (f - wk) / kap
                    f = wk
                elif f < -wk:
                    if kap > 0.0:
                        diss += wk * (-wk - f) / kap
                    f = -wk
                x[HZ + k] = f
                t_h += f
        t_d = p[CDAMP] * ddth
        t_k = spring_torque(dth, p, flags) + t_d + t_h
        x[TK] = t_k
        # --- amplifier and current loop
        i_t = i_cmd
        if flags & AMP:
            imax = p[I_MAX]
            if i_t > imax:
                i_t = imax
            elif i_t < -imax:
                i_t = -imax
            hi = (p[V_MAX] - p[KB] * w_m) / p[RES]
            lo = (-p[V_MAX] - p[KB] * w_m) / p[RES]
            if i_t > hi:
                i_t = hi
            elif i_t < lo:
                i_t = lo
        cur = x[CUR] + alpha * (i_t - x[CUR])
        x[CUR] = cur
        t_m = p[KT] * cur
        x[T_MOTOR] = t_m
        # --- motor side
        lvl = _friction_level(p, FIN, w_m, th_m, th_o, 0.0, flags)
        vis = _viscous_coeff(p, FIN, w_m, flags)
        w_m_new, pm = _advance(w_m, t_m - t_k * gear, jm, vis, lvl, dt)
        # --- output side
        t_load = p[LOAD_T] + t_ext
        if p[GRAV] != 0.0:
            t_load += p[GRAV] * math.sin(th_o)
        if locked:
            w_o_new = 0.0
            po = 0.0
        else:
            lvl = _friction_level(p, FOUT, w_o, th_m, th_o, mu * abs(t_k), flags)
            vis = _viscous_coeff(p, FOUT, w_o, flags)
            w_o_new, po = _advance(w_o, t_k - t_load, jo, vis, lvl, dt)
        x[T_LOAD] = t_load
        # --- positions and bookkeeping
        x[W_M] = w_m_new
        x[W_O] = w_o_new
        x[TH_M] = th_m + dt * w_m_new
        x[TH_O] = th_o + dt * w_o_new
        x[E_DISS] += dt * (pm + po + p[CDAMP] * ddth * ddth) + diss
        x[W_MOTOR] += dt * t_m * w_m_new
        x[W_LOAD] -= dt * t_load * w_o_new


@_jit
def _bad(x: np.ndarray) -> bool:
    for k in range(x.shape[0]):
        if not math.isfinite(x[k]):
            return True
    return abs(x[W_M]) > 1e7 or abs(x[TK]) > 1e9


@nb.njit(cache=True, parallel=True, nogil=True)
def step_parallel(xs: np.ndarray, ps: np.ndarray, i_cmd: np.ndarray, t_ext: np.ndarray,
                  dt: float, n_sub: int, flags: np.ndarray, bad: np.ndarray) -> None:
    """Advance a batch ``xs (n, N_STATE)`` with parameters ``ps (n, N_PARAMS)`` (threads)."""
    for e in nb.prange(xs.shape[0]):
        substeps(xs[e], ps[e], i_cmd[e], t_ext[e], dt, n_sub, flags[e])
        bad[e] = _bad(xs[e])


@_jit
def step_serial(xs: np.ndarray, ps: np.ndarray, i_cmd: np.ndarray, t_ext: np.ndarray,
                dt: float, n_sub: int, flags: np.ndarray, bad: np.ndarray) -> None:
    """Same as :func:`step_parallel` on one thread (cheaper for small batches)."""
    for e in range(xs.shape[0]):
        substeps(xs[e], ps[e], i_cmd[e], t_ext[e], dt, n_sub, flags[e])
        bad[e] = _bad(xs[e])


#: batch size from which the threaded step beats one thread (measured on 2 cores with
#: the work-queue layer: serial 1.13M vs threaded 1.14M env-steps/s at 512 envs,
#: 1.13M vs 1.31M at 1,024; below 512 the launch overhead dominates)
PARALLEL_THRESHOLD = 1024


def step_for(n_envs: int):
    """The batch step to use for ``n_envs`` environments."""
    return step_parallel if n_envs >= PARALLEL_THRESHOLD else step_serial


@_jit
def run_open_loop(x: np.ndarray, p: np.ndarray, i_cmd: np.ndarray, t_ext: np.ndarray,
                  dt: float, n_sub: int, flags: int, out: np.ndarray) -> int:
    """Run one env through a whole command sequence, recording the state after each step.

    ``out`` has shape ``(len(i_cmd), N_STATE)``. Returns the index of the
    first step whose state diverged, or -1.
    """
    for k in range(i_cmd.shape[0]):
        substeps(x, p, i_cmd[k], t_ext[k], dt, n_sub, flags)
        for j in range(N_STATE):
            out[k, j] = x[j]
        if _bad(x):
            return k
    return -1
