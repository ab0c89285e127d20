"""The compiled joint step (numba), one env at a time: docs/physics.md eqs. (1)-(13).

Long because: the substep and the helpers numba inlines into it stay
in one file, so a reader sees the whole step beside the equations it cites.

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

This module steps one env at a time (single trajectories: the Simulator,
the discrepancy fits, closed loops); the kinematic-error, ripple and
gravity phases are computed exactly once per call and rotated by each
substep's angle increment. Batches of envs run the same step in SIMD lanes,
:mod:`hdgym.physics.lanes`.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from hdgym.effects import BIT, LOCKED_OUTPUT_BIT
from hdgym.params import MAX_HARMONICS, MAX_RIPPLES
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
    MESH,
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
    STARTUP1,
    T_LOAD,
    T_MOTOR,
    TANH_B,
    TANH_B1,
    TANH_G,
    TANH_G1,
    TH_M,
    TH_O,
    TK,
    V_MAX,
    W_LOAD,
    W_M,
    W_MOTOR,
    W_O,
)

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

#: torsion increments (rad) below which the tanh hysteresis model does not
#: register a reversal: rounding noise at standstill (1e-17 rad) must not
#: restart its loop, while the slowest physical motion moves 1e-10 rad per substep
REVERSAL_DEADBAND = 1e-14

_jit = nb.njit(cache=True, fastmath={"contract"}, nogil=True)
_inl = nb.njit(cache=True, fastmath={"contract"}, nogil=True, inline="always")


@_inl
def spring_torque(x: float, p: np.ndarray, flags: int) -> float:
    """Spring torque of the flexspline at torsion ``x`` (output rad), N m: eq. (3)."""
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


@_inl
def _coulomb_level(p: np.ndarray, base: int, w: float, flags: int) -> float:
    """Coulomb, Stribeck and stiction level (>= 0) at speed ``w``; ``w == 0`` means stuck:
    eq. (7)."""
    if not (flags & COUL):
        return 0.0
    fc = p[base + F_FC]
    if w == 0.0:
        return p[base + F_FS] if (flags & (STICK | STRIB)) else fc
    if flags & STRIB:
        r = w / p[base + F_WS]
        r2 = r * r
        # exp(-40) < 5e-18: skip the call far above the Stribeck speed
        return fc + (p[base + F_FS] - fc) * math.exp(-r2) if r2 < 40.0 else fc
    return fc


@_jit
def _friction_level(p: np.ndarray, base: int, w: float, th_in: float, th_out: float,
                    extra: float, flags: int) -> float:
    """Coulomb-type friction level (>= 0) at speed ``w``; ``w == 0`` means stuck."""
    level = _coulomb_level(p, base, w, flags)
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
    mode, b1, b2, wpk2, fpk = viscous_constants(p, base, flags)
    return _visc(mode, b1, b2, wpk2, fpk, w)


# ---------------------------------------------------------------- the fast path
# The substep below is what every env step runs ten times, so it avoids what
# costs there: divisions (per-call reciprocals instead), and sin/cos of the
# kinematic-error and friction-ripple phases (computed exactly once per call,
# then rotated by each substep's angle increment with a short Taylor series).

#: phases tracked per env: kinematic-error harmonics, input and output ripples, gravity arm
N_PHASES = MAX_HARMONICS + 2 * MAX_RIPPLES + 1
_RIP0 = (MAX_HARMONICS, MAX_HARMONICS + MAX_RIPPLES)  # first ripple phase, per friction side
_GRAV_PHASE = N_PHASES - 1
#: scratch floats one env needs (sin, then cos, of every phase)
SCRATCH = 2 * N_PHASES


@_inl
def sincos_small(d: float) -> tuple[float, float]:
    """sin and cos of |d| < 0.3 (Taylor to d^13 / d^14: truncation below 3e-17)."""
    z = d * d
    sd = d * (1.0 + z * (-1.0 / 6.0 + z * (1.0 / 120.0 + z * (
        -1.0 / 5040.0 + z * (1.0 / 362880.0 + z * (-1.0 / 39916800.0 + z / 6227020800.0))))))
    cd = 1.0 + z * (-0.5 + z * (1.0 / 24.0 + z * (-1.0 / 720.0 + z * (
        1.0 / 40320.0 + z * (-1.0 / 3628800.0 + z / 479001600.0)))))
    return sd, cd


@_inl
def _rotate(trig: np.ndarray, j: int, d: float) -> None:
    """Advance phase ``j`` of ``trig`` (sines, then cosines) by ``d`` rad."""
    if abs(d) < 0.3:
        sd, cd = sincos_small(d)
    else:
        sd = math.sin(d)
        cd = math.cos(d)
    s = trig[j]
    c = trig[N_PHASES + j]
    trig[j] = s * cd + c * sd
    trig[N_PHASES + j] = c * cd - s * sd


@_jit
def _set_phase(trig: np.ndarray, j: int, a: float) -> None:
    trig[j] = math.sin(a)
    trig[N_PHASES + j] = math.cos(a)


@_jit
def _init_ripples(trig: np.ndarray, p: np.ndarray, side: int, base: int, th_m: float,
                  th_o: float) -> int:
    """Exact phases of one side's friction ripples; returns how many there are."""
    nrip = int(p[base + F_NRIP])
    for k in range(nrip):
        ang = th_m if p[base + F_RFRAME + k] == 0.0 else th_o
        _set_phase(trig, _RIP0[side] + k, p[base + F_RORD + k] * ang + p[base + F_RPH + k])
    return nrip


@_inl
def _rotate_ripples(trig: np.ndarray, p: np.ndarray, side: int, base: int, nrip: int,
                    d_m: float, d_o: float) -> None:
    for k in range(nrip):
        d = d_m if p[base + F_RFRAME + k] == 0.0 else d_o
        _rotate(trig, _RIP0[side] + k, p[base + F_RORD + k] * d)


@_inl
def _level(p: np.ndarray, base: int, w: float, extra: float, flags: int, trig: np.ndarray,
           rip0: int, nrip: int) -> float:
    """:func:`_friction_level` with the ripple sines taken from ``trig``."""
    level = _coulomb_level(p, base, w, flags)
    for k in range(nrip):
        level += p[base + F_RAMP + k] * trig[rip0 + k]
    level += extra
    return level if level > 0.0 else 0.0


@_jit
def viscous_constants(p: np.ndarray, base: int,
                      flags: int) -> tuple[int, float, float, float, float]:
    """(mode, b1, b2, w_pk^2, f(w_pk)) of one side (eq. (7)); mode 0 off, 1 linear, 2 cubic,
    3 capped."""
    if not (flags & VISC):
        return 0, 0.0, 0.0, 0.0, 0.0
    b1 = p[base + F_B1]
    b2 = p[base + F_B2]
    if b2 == 0.0:
        return 1, b1, 0.0, 0.0, 0.0
    if b2 > 0.0:
        return 2, b1, b2, 0.0, 0.0
    wpk2 = b1 / (-3.0 * b2)
    wpk = math.sqrt(wpk2)
    return 3, b1, b2, wpk2, b1 * wpk + b2 * wpk2 * wpk


@_inl
def _visc(mode: int, b1: float, b2: float, wpk2: float, fpk: float, w: float) -> float:
    """:func:`_viscous_coeff` from the constants of :func:`viscous_constants` (eq. (7))."""
    if mode <= 1:
        return b1
    w2 = w * w
    if mode == 2 or w2 <= wpk2:
        return b1 + b2 * w2
    return fpk / abs(w)


@_inl
def _advance(w: float, tau: float, h: float, visc: float, level: float) -> tuple[float, float]:
    """New speed under torque ``tau``, implicit viscous and bounded Coulomb impulse. Eq. (11).

    ``h`` is the substep over the inertia (s/(kg m^2)). Returns (new speed,
    dissipated power).
    """
    inv = 1.0 / (1.0 + h * visc)
    v_free = (w + h * tau) * inv
    dv = h * level * inv
    if abs(v_free) <= dv:
        return 0.0, 0.0
    v = v_free - math.copysign(dv, v_free)
    return v, visc * v * v + level * abs(v)


@_jit
def substeps(x: np.ndarray, p: np.ndarray, i_cmd: float, t_ext: float, dt: float,
             n_sub: int, flags: int, trig: np.ndarray) -> None:
    """Advance one env's state ``x`` in place by ``n_sub`` substeps of ``dt`` s.

    ``i_cmd`` is the current command (A); ``t_ext`` an external load torque
    (N m, resisting positive output motion) added to the preset's load.
    ``trig`` is the caller's scratch of :data:`SCRATCH` floats (the phases'
    sin and cos), reused from call to call.
    """
    r = p[RATIO]
    inv_r = 1.0 / r
    h_m = dt / p[J_M]
    h_o = dt / p[J_O]
    alpha = 1.0 - math.exp(-2.0 * math.pi * p[BW] * dt)
    locked = (flags & LOCKED) != 0
    nke = int(p[NKE]) if (flags & KE) else 0
    hyst_on = (flags & HYST) != 0
    # the tanh element's memory runs with hysteresis off too: it holds the load
    # history the startup torque grows with (docs/physics.md eqs. H3, H4)
    tanh_model = p[HMODEL] == 1.0
    nslip = int(p[NSLIP]) if hyst_on and not tanh_model else 0
    startup = p[STARTUP1] if (tanh_model and (flags & LOADDEP)) else 0.0
    mu = p[MU_LOAD] if (flags & LOADDEP) else 0.0
    mesh = p[MESH] == 1.0
    # eq. (8), placement splines: the torque sensor reads the grounded spline's torque,
    # the output's inertial torque plus the load (not with the output locked)
    sense = p[MESH] == 2.0 and not locked
    jo_dt = p[J_O] / dt
    amp_on = (flags & AMP) != 0
    imax = p[I_MAX]
    inv_res = 1.0 / p[RES]
    v_hi = p[V_MAX] * inv_res
    kb_r = p[KB] * inv_res
    kt = p[KT]
    cdamp = p[CDAMP]
    grav = p[GRAV]
    t_load0 = p[LOAD_T] + t_ext
    vm_mode, vm_b1, vm_b2, vm_pk2, vm_fpk = viscous_constants(p, FIN, flags)
    vo_mode, vo_b1, vo_b2, vo_pk2, vo_fpk = viscous_constants(p, FOUT, flags)
    th_m = x[TH_M]
    th_o = x[TH_O]
    for k in range(nke):
        _set_phase(trig, k, p[KE_ORD + k] * th_m + p[KE_PH + k])
    if grav != 0.0:
        _set_phase(trig, _GRAV_PHASE, th_o)
    nrip_in = 0
    nrip_out = 0
    if flags & POSDEP:
        nrip_in = _init_ripples(trig, p, 0, FIN, th_m, th_o)
        nrip_out = _init_ripples(trig, p, 1, FOUT, th_m, th_o)
    w_m = x[W_M]
    w_o = x[W_O]
    cur = x[CUR]
    dth_prev = x[DTH]
    e_diss = x[E_DISS]
    w_motor = x[W_MOTOR]
    w_load = x[W_LOAD]
    t_k = x[TK]
    t_s = t_k  # the state's torque: T_k, or the grounded spline's torque (eq. 8)
    t_m = x[T_MOTOR]
    t_load = x[T_LOAD]
    for _ in range(n_sub):
        # --- kinematic error and torsion: eqs. (1), (2)
        ke = 0.0
        dke = 0.0
        for k in range(nke):
            amp = p[KE_AMP + k]
            ke += amp * trig[k]
            dke += amp * p[KE_ORD + k] * trig[N_PHASES + k]
        dth = th_m * inv_r - th_o - ke
        gear = inv_r - dke
        ddth = w_m * gear - w_o
        d_inc = dth - dth_prev
        dth_prev = dth
        # --- hysteresis: eq. (5) (tanh) or eq. (4) (Maxwell-slip)
        t_h = 0.0
        diss = 0.0
        if tanh_model:
            # Seyfferth eq. 4, load-history parameters: docs/physics.md eqs. H1-H3
            s = x[HZ + 2]
            load = x[HZ + 4]
            a_k = abs(t_s)  # |transmitted torque| at the previous substep (= T* at a reversal)
            if a_k > load:
                load = a_k
            if abs(d_inc) > REVERSAL_DEADBAND:
                s_new = 1.0 if d_inc > 0.0 else -1.0
                if s_new != s:  # reversal: remember where, how much and the load there
                    x[HZ] = dth - d_inc
                    x[HZ + 1] = x[HZ + 3]
                    x[HZ + 5] = 1.0 if s == 0.0 else 0.0  # the first move stays virgin
                    x[HZ + 2] = s_new
                    s = s_new
                    load = a_k
            x[HZ + 4] = load
            if hyst_on:
                dts = x[HZ + 1]
                gam = p[TANH_G] + p[TANH_G1] * load
                gam = (1.0 + x[HZ + 5]) * gam if gam > 0.0 else 0.0  # virgin curve: 2 gamma
                t_h = dts + (s * (p[TANH_B] + p[TANH_B1] * load) - dts) * math.tanh(
                    gam * s * (dth - x[HZ]))
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
        # eqs. (3), (6)
        t_k = spring_torque(dth, p, flags) + cdamp * ddth + t_h
        # --- amplifier and current loop: eqs. (9), (10)
        i_t = i_cmd
        if amp_on:
            if i_t > imax:
                i_t = imax
            elif i_t < -imax:
                i_t = -imax
            back = kb_r * w_m
            if i_t > v_hi - back:
                i_t = v_hi - back
            elif i_t < -v_hi - back:
                i_t = -v_hi - back
        cur = cur + alpha * (i_t - cur)
        t_m = kt * cur
        # --- motor side: friction eq. (7) with the startup torque eq. H4, speed eq. (11)
        lvl = _level(p, FIN, w_m, startup * x[HZ + 4], flags, trig, _RIP0[0], nrip_in)
        vis = _visc(vm_mode, vm_b1, vm_b2, vm_pk2, vm_fpk, w_m)
        if mesh:
            # eq. (8): the transmission friction at the mesh speed, seen by the WG through `gear`
            v_g = w_m * gear
            lvl += gear * _level(p, FOUT, v_g, mu * abs(t_k), flags, trig, _RIP0[1], nrip_out)
            vis += gear * gear * _visc(vo_mode, vo_b1, vo_b2, vo_pk2, vo_fpk, v_g)
        w_m_new, pm = _advance(w_m, t_m - t_k * gear, h_m, vis, lvl)
        # --- output side: friction eqs. (7), (8), speed eq. (11)
        t_load = t_load0
        if grav != 0.0:
            t_load += grav * trig[_GRAV_PHASE]
        if locked:
            w_o_new = 0.0
            po = 0.0
        elif mesh:
            w_o_new, po = _advance(w_o, t_k - t_load, h_o, 0.0, 0.0)
        else:
            lvl = _level(p, FOUT, w_o, mu * abs(t_k), flags, trig, _RIP0[1], nrip_out)
            vis = _visc(vo_mode, vo_b1, vo_b2, vo_pk2, vo_fpk, w_o)
            w_o_new, po = _advance(w_o, t_k - t_load, h_o, vis, lvl)
        # eq. (8), placement splines: the sensor reads J_o dw_o/dt + T_load
        t_s = (w_o_new - w_o) * jo_dt + t_load if sense else t_k
        # --- angles eq. (12), bookkeeping eq. (13), the phases of the new angles eq. (1)
        d_m = dt * w_m_new
        d_o = dt * w_o_new
        w_m = w_m_new
        w_o = w_o_new
        th_m = th_m + d_m
        th_o = th_o + d_o
        e_diss += dt * (pm + po + cdamp * ddth * ddth) + diss
        w_motor += dt * t_m * w_m_new
        w_load -= dt * t_load * w_o_new
        for k in range(nke):
            _rotate(trig, k, p[KE_ORD + k] * d_m)
        if nrip_in:
            _rotate_ripples(trig, p, 0, FIN, nrip_in, d_m, d_o)
        if nrip_out:
            _rotate_ripples(trig, p, 1, FOUT, nrip_out, d_m, d_o)
        if grav != 0.0:
            _rotate(trig, _GRAV_PHASE, d_o)
    x[TH_M] = th_m
    x[W_M] = w_m
    x[TH_O] = th_o
    x[W_O] = w_o
    x[CUR] = cur
    x[TK] = t_s
    x[DTH] = dth_prev
    x[E_DISS] = e_diss
    x[W_MOTOR] = w_motor
    x[W_LOAD] = w_load
    x[T_LOAD] = t_load
    x[T_MOTOR] = t_m


@_jit
def _bad(x: np.ndarray) -> bool:
    for k in range(x.shape[0]):
        if not math.isfinite(x[k]):
            return True
    return abs(x[W_M]) > 1e7 or abs(x[TK]) > 1e9


#: envs per scratch buffer in the threaded step
_CHUNK = 32


@nb.njit(cache=True, parallel=True, nogil=True)
def step_parallel(xs: np.ndarray, ps: np.ndarray, i_cmd: np.ndarray, t_ext: np.ndarray,
                  dt: float, n_sub: int, flags: np.ndarray, bad: np.ndarray) -> None:
    """Advance a batch ``xs (n, N_STATE)`` with parameters ``ps (n, N_PARAMS)`` (threads)."""
    n = xs.shape[0]
    for c in nb.prange((n + _CHUNK - 1) // _CHUNK):
        trig = np.empty(SCRATCH)
        for e in range(c * _CHUNK, min(n, (c + 1) * _CHUNK)):
            substeps(xs[e], ps[e], i_cmd[e], t_ext[e], dt, n_sub, flags[e], trig)
            bad[e] = _bad(xs[e])


@_jit
def step_serial(xs: np.ndarray, ps: np.ndarray, i_cmd: np.ndarray, t_ext: np.ndarray,
                dt: float, n_sub: int, flags: np.ndarray, bad: np.ndarray) -> None:
    """Same as :func:`step_parallel` on one thread (cheaper for small batches)."""
    trig = np.empty(SCRATCH)
    for e in range(xs.shape[0]):
        substeps(xs[e], ps[e], i_cmd[e], t_ext[e], dt, n_sub, flags[e], trig)
        bad[e] = _bad(xs[e])


#: batch size from which the threaded step beats one thread (with the TBB layer on
#: 2 cores: serial 37 vs threaded 29 us per step at 64 envs, 146 vs 91 at 256;
#: batches of many envs are faster still in :mod:`hdgym.physics.lanes`)
PARALLEL_THRESHOLD = 64


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
    trig = np.empty(SCRATCH)
    for k in range(i_cmd.shape[0]):
        substeps(x, p, i_cmd[k], t_ext[k], dt, n_sub, flags, trig)
        for j in range(N_STATE):
            out[k, j] = x[j]
        if _bad(x):
            return k
    return -1
