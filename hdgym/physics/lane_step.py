"""The joint's substep for a block of SIMD lanes (:func:`run_block`).

Every substep is a handful of passes over a block, each pass a branch-free
loop over its envs that the compiler turns into vector instructions (8 envs
per instruction with AVX-512, 4 with AVX2): torsion and kinematic error,
Maxwell-slip elements, tanh hysteresis (scalar, only where a lane uses it),
friction ripples, then drive and motion in one pass, then the phases. The
physics is :mod:`hdgym.physics.kernel`'s semi-implicit step, operation for
operation; the tests hold both to the numpy reference
(:mod:`hdgym.physics.reference`). The block's fields are
:mod:`hdgym.physics.lane_fields`.
"""

from __future__ import annotations

import math

import numpy as np

from hdgym.physics import layout as L
from hdgym.physics.kernel import REVERSAL_DEADBAND, sincos_small
from hdgym.physics.lane_fields import (
    ALPHA,
    BAD,
    BLOCK,
    CDAMP,
    CMODEL,
    COS,
    COUNT,
    DT,
    F_B1,
    F_B2,
    F_FC,
    F_FPK,
    F_FS,
    F_PK2,
    F_RA,
    F_RF,
    F_RO,
    F_STRIB,
    F_STUCK,
    F_WS,
    GRAV,
    H_M,
    H_O,
    ICMD,
    IMAX,
    INV_R,
    JO_DT,
    K0,
    K1,
    K3,
    KBR,
    KE_A,
    KE_AO,
    KE_O,
    KNEE,
    KT,
    LOAD0,
    LOCK,
    MESH,
    MU,
    NKE,
    NRIP_IN,
    NRIP_OUT,
    NSLIP,
    P_GRAV,
    P_KE,
    P_RIP,
    RESYNC,
    SENSE,
    SIDE,
    SIN,
    SK2,
    SK3,
    SLIP_K,
    SLIP_W,
    SLIP_WK,
    ST1,
    ST2,
    STARTUP,
    T_D,
    T_DDTH,
    T_DINC,
    T_DISS,
    T_DKE,
    T_DM,
    T_DO,
    T_DTH,
    T_GEAR,
    T_KE,
    T_LIN,
    T_LOUT,
    T_TH,
    TANH,
    TANH_B,
    TANH_B1,
    TANH_G,
    TANH_G1,
    TANH_ON,
    TEXT,
    TH1,
    TH2,
    VHI,
    inline_lane,
    jit_lane,
    sync_lane,
)
from hdgym.physics.lane_fields import get as _g
from hdgym.physics.lane_fields import put as _s


@inline_lane
def _sincos_tiny(d: float) -> tuple[float, float]:
    """sin and cos of |d| < 0.05 (Taylor to d^9 / d^10: truncation below 2e-22)."""
    z = d * d
    sd = d * (1.0 + z * (-1.0 / 6.0 + z * (1.0 / 120.0 + z * (
        -1.0 / 5040.0 + z / 362880.0))))
    cd = 1.0 + z * (-0.5 + z * (1.0 / 24.0 + z * (-1.0 / 720.0 + z * (
        1.0 / 40320.0 - z / 3628800.0))))
    return sd, cd


@inline_lane
def _turn(w: np.ndarray, ph: int, j: int, sd: float, cd: float) -> None:
    """Rotate phase ``ph`` of lane ``j`` by the angle whose sine and cosine are given."""
    s = _g(w, SIN + ph, j)
    c = _g(w, COS + ph, j)
    _s(w, SIN + ph, j, s * cd + c * sd)
    _s(w, COS + ph, j, c * cd - s * sd)


@inline_lane
def _rotate(w: np.ndarray, nl: int, ph: int) -> None:
    """Rotate phase ``ph`` of every lane by its increment in field T_D.

    Each lane's series depends on its own increment only (|d| < 0.05: the short
    series; < 0.3: the longer one; else exact sin/cos), so an env's result does
    not depend on its block mates; the block-wide tests only pick the cheapest
    loop that gives every lane its own choice.
    """
    mid = 0
    big = 0
    for j in range(nl):
        a = abs(_g(w, T_D, j))
        mid += 1 if a >= 0.05 else 0
        big += 1 if a >= 0.3 else 0
    if mid == 0:  # the usual case at 10 substeps per ms: a short series, vectorized
        for j in range(nl):
            sd, cd = _sincos_tiny(_g(w, T_D, j))
            _turn(w, ph, j, sd, cd)
    elif big == 0:  # both series in every lane, each lane keeps its own: still vectorized
        for j in range(nl):
            d = _g(w, T_D, j)
            st, ct = _sincos_tiny(d)
            ss, cs = sincos_small(d)
            tiny = abs(d) < 0.05
            _turn(w, ph, j, st if tiny else ss, ct if tiny else cs)
    else:
        for j in range(nl):  # coarse substeps or very fast motors
            d = _g(w, T_D, j)
            if abs(d) < 0.05:
                sd, cd = _sincos_tiny(d)
            elif abs(d) < 0.3:
                sd, cd = sincos_small(d)
            else:
                sd = math.sin(d)
                cd = math.cos(d)
            _turn(w, ph, j, sd, cd)


@inline_lane
def _spring(w: np.ndarray, j: int, x: float) -> float:
    """Spring torque, branch-free form of :func:`hdgym.physics.kernel.spring_torque`: eq. (3)."""
    k1 = _g(w, K1, j)
    model = _g(w, CMODEL, j)
    lin = k1 * x
    ax = abs(x)
    s = math.copysign(1.0, x)
    cub = k1 * x + _g(w, K3, j) * x * x * x
    knee = _g(w, KNEE, j)
    two = lin if ax <= knee else k1 * x + _g(w, K0, j) * (ax - knee) * s
    th1 = _g(w, TH1, j)
    th2 = _g(w, TH2, j)
    mid = s * (_g(w, ST1, j) + _g(w, SK2, j) * (ax - th1))
    top = s * (_g(w, ST2, j) + _g(w, SK3, j) * (ax - th2))
    three = lin if ax <= th1 else (mid if ax <= th2 else top)
    out = lin
    out = cub if model == 1.0 else out
    out = two if model == 2.0 else out
    return three if model == 3.0 else out


@inline_lane
def _advance(v0: float, tau: float, h: float, visc: float, level: float) -> tuple[float, float]:
    """New speed and dissipated power, branch-free form of :func:`kernel._advance`: eq. (11)."""
    inv = 1.0 / (1.0 + h * visc)
    v_free = (v0 + h * tau) * inv
    dv = h * level * inv
    stuck = abs(v_free) <= dv
    v = v_free - dv if v_free > 0.0 else v_free + dv
    v = 0.0 if stuck else v
    pw = 0.0 if stuck else visc * v * v + level * abs(v)
    return v, pw


@inline_lane
def _visc(w: np.ndarray, at: int, j: int, v: float) -> float:
    """Secant viscous coefficient (see :func:`kernel._viscous_coeff`): eq. (7)."""
    v2 = v * v
    below = _g(w, at + F_B1, j) + _g(w, at + F_B2, j) * v2
    capped = _g(w, at + F_FPK, j) / abs(v)
    return below if v2 <= _g(w, at + F_PK2, j) else capped


@inline_lane
def _block_max(w: np.ndarray, nl: int, f: int) -> int:
    m = 0.0
    for j in range(nl):
        m = max(m, _g(w, f, j))
    return int(m)


@inline_lane
def _tanh_hysteresis(w: np.ndarray, nl: int) -> None:
    """The tanh hysteresis model for the lanes that use it (scalar: it needs tanh): eq. (5)."""
    hz = L.HZ
    for j in range(nl):
        if _g(w, TANH, j) == 0.0:
            continue
        # Seyfferth eq. 4, load-history parameters: docs/physics.md eqs. H1-H3
        dth = _g(w, T_DTH, j)
        d_inc = _g(w, T_DINC, j)
        s = _g(w, hz + 2, j)
        a_k = abs(_g(w, L.TK, j))  # the previous substep's transmitted torque
        load = max(_g(w, hz + 4, j), a_k)
        if abs(d_inc) > REVERSAL_DEADBAND:
            s_new = 1.0 if d_inc > 0.0 else -1.0
            if s_new != s:  # reversal: remember where, how much and the load there
                _s(w, hz, j, dth - d_inc)
                _s(w, hz + 1, j, _g(w, hz + 3, j))
                _s(w, hz + 5, j, 1.0 if s == 0.0 else 0.0)  # the first move stays virgin
                _s(w, hz + 2, j, s_new)
                s = s_new
                load = a_k
        _s(w, hz + 4, j, load)
        # startup torque grown with the load history (eq. H4), added to the input's ripple sum
        _s(w, T_LIN, j, _g(w, T_LIN, j) + _g(w, STARTUP, j) * load)
        if _g(w, TANH_ON, j) == 0.0:
            continue
        dts = _g(w, hz + 1, j)
        # virgin curve: twice the shape factor (eq. H1, Masing's rule)
        gam = (1.0 + _g(w, hz + 5, j)) * max(_g(w, TANH_G, j) + _g(w, TANH_G1, j) * load, 0.0)
        t_h = dts + (s * (_g(w, TANH_B, j) + _g(w, TANH_B1, j) * load) - dts) * math.tanh(
            gam * s * (dth - _g(w, hz, j)))
        _s(w, hz + 3, j, t_h)
        _s(w, T_TH, j, t_h)


#: 2**-k for k = 0..63, for :func:`_exp_neg`
_POW2_NEG = np.array([2.0 ** -k for k in range(64)])
_LN2_HI = 6.93147180369123816490e-01  # ln 2 split so k * _LN2_HI is exact (fdlibm)
_LN2_LO = 1.90821492927058770002e-10


@inline_lane
def _exp_neg(x: float) -> float:
    """exp(-x) for 0 <= x <= 40 (within 2 ulp of libm), in a form that vectorizes:
    exp(-x) = 2**-k exp(u), k = round(x / ln 2), |u| <= ln(2)/2, exp(u) by Taylor to u^13."""
    # callers keep 0 <= x <= 40 (NaN mapped to 40): k indexes the table unchecked
    k = math.floor(x * 1.4426950408889634 + 0.5)
    u = (k * _LN2_HI - x) + k * _LN2_LO
    e = 1.0 + u * (1.0 + u * (1.0 / 2.0 + u * (1.0 / 6.0 + u * (1.0 / 24.0 + u * (
        1.0 / 120.0 + u * (1.0 / 720.0 + u * (1.0 / 5040.0 + u * (1.0 / 40320.0 + u * (
            1.0 / 362880.0 + u * (1.0 / 3628800.0 + u * (1.0 / 39916800.0 + u * (
                1.0 / 479001600.0 + u / 6227020800.0))))))))))))
    return _POW2_NEG[int(k)] * e


@inline_lane
def _torsion(w: np.ndarray, nl: int, nke: int) -> None:
    """Kinematic error, torsion, gear factor, torsion rate and increment: eqs. (1), (2)."""
    for j in range(nl):
        _s(w, T_KE, j, 0.0)
        _s(w, T_DKE, j, 0.0)
    for k in range(nke):
        for j in range(nl):
            _s(w, T_KE, j, _g(w, T_KE, j) + _g(w, KE_A + k, j) * _g(w, SIN + P_KE + k, j))
            _s(w, T_DKE, j, _g(w, T_DKE, j) + _g(w, KE_AO + k, j) * _g(w, COS + P_KE + k, j))
    for j in range(nl):
        inv_r = _g(w, INV_R, j)
        dth = _g(w, L.TH_M, j) * inv_r - _g(w, L.TH_O, j) - _g(w, T_KE, j)
        gear = inv_r - _g(w, T_DKE, j)
        _s(w, T_DTH, j, dth)
        _s(w, T_GEAR, j, gear)
        _s(w, T_DDTH, j, _g(w, L.W_M, j) * gear - _g(w, L.W_O, j))
        _s(w, T_DINC, j, dth - _g(w, L.DTH, j))
        _s(w, L.DTH, j, dth)
        _s(w, T_TH, j, 0.0)
        _s(w, T_DISS, j, 0.0)


@inline_lane
def _maxwell(w: np.ndarray, nl: int, nslip: int) -> None:
    """Maxwell-slip elements and their slip dissipation: eq. (4)."""
    for k in range(nslip):
        hz = L.HZ + k
        for j in range(nl):
            kap = _g(w, SLIP_K + k, j)
            wk = _g(w, SLIP_W + k, j)
            f0 = _g(w, hz, j)
            f = f0 + kap * _g(w, T_DINC, j)
            up = f > wk
            down = f < -wk
            # energy of the slip: W/kappa times the force beyond W
            wdk = _g(w, SLIP_WK + k, j)
            dd = (f - wk) * wdk if up else ((-wk - f) * wdk if down else 0.0)
            f = wk if up else (-wk if down else f)
            on = k < _g(w, NSLIP, j)
            _s(w, hz, j, f if on else f0)
            _s(w, T_TH, j, _g(w, T_TH, j) + (f if on else 0.0))
            _s(w, T_DISS, j, _g(w, T_DISS, j) + (dd if on else 0.0))


@inline_lane
def _ripple_sums(w: np.ndarray, nl: int, nrin: int, nrout: int) -> None:
    """Position-dependent friction of each side, summed over its ripples, into T_LIN/T_LOUT:
    the ripple term of eq. (7)."""
    for side in range(2):
        at = SIDE[side] + F_RA
        out = T_LIN if side == 0 else T_LOUT
        for j in range(nl):
            _s(w, out, j, 0.0)
        for k in range(nrin if side == 0 else nrout):
            for j in range(nl):
                _s(w, out, j, _g(w, out, j) + _g(w, at + k, j) * _g(w, SIN + P_RIP[side] + k, j))


@inline_lane
def _level(w: np.ndarray, at: int, j: int, v: float, ripple: float) -> float:
    """Coulomb-type level of one side at speed ``v`` (0: stuck) before the load term:
    Coulomb or breakaway, the Stribeck hump, plus the ripple sum. Eq. (7)."""
    fc = _g(w, at + F_FC, j)
    stuck = _g(w, at + F_STUCK, j)  # loaded before the select: a conditional load
    base = stuck if v == 0.0 else fc  # would keep the loop from vectorizing
    r = v / _g(w, at + F_WS, j)
    r2 = r * r
    # exp(-40) < 5e-18: the hump is gone far above the Stribeck speed
    on = _g(w, at + F_STRIB, j) != 0.0 and v != 0.0 and r2 < 40.0
    hump = fc + (_g(w, at + F_FS, j) - fc) * _exp_neg(r2 if r2 < 40.0 else 40.0)
    return (hump if on else base) + ripple


@inline_lane
def _drive_and_move(w: np.ndarray, nl: int) -> None:
    """Transmitted torque, amplifier and current loop, friction, new speeds and
    angles, energy bookkeeping: one pass, so the temporaries stay in registers."""
    a_in = SIDE[0]
    a_out = SIDE[1]
    for j in range(nl):
        # --- transmitted torque: eqs. (3), (6)
        t_k = _spring(w, j, _g(w, T_DTH, j)) + _g(w, CDAMP, j) * _g(w, T_DDTH, j) \
            + _g(w, T_TH, j)
        # --- amplifier and current loop: eqs. (9), (10)
        w_m = _g(w, L.W_M, j)
        w_o = _g(w, L.W_O, j)
        imax = _g(w, IMAX, j)
        i_t = _g(w, ICMD, j)
        i_t = imax if i_t > imax else (-imax if i_t < -imax else i_t)
        back = _g(w, KBR, j) * w_m
        v_hi = _g(w, VHI, j)
        hi_i = v_hi - back
        lo_i = -v_hi - back
        i_t = hi_i if i_t > hi_i else (lo_i if i_t < lo_i else i_t)
        cur = _g(w, L.CUR, j)
        cur = cur + _g(w, ALPHA, j) * (i_t - cur)
        _s(w, L.CUR, j, cur)
        t_m = _g(w, KT, j) * cur
        _s(w, L.T_MOTOR, j, t_m)
        # --- transmission friction (eq. 8): at the output speed, or at the mesh speed
        # w_m * gear and reflected to the WG by gear (placement mesh)
        gear = _g(w, T_GEAR, j)
        mesh = _g(w, MESH, j) != 0.0  # 1 for the mesh placement only (lane_fields)
        v_rel = w_m * gear if mesh else w_o
        lvl_t = _level(w, a_out, j, v_rel, _g(w, T_LOUT, j)) + _g(w, MU, j) * abs(t_k)
        lvl_t = lvl_t if lvl_t > 0.0 else 0.0
        vis_t = _visc(w, a_out, j, v_rel)
        g_m = gear if mesh else 0.0
        # --- motor side: friction eq. (7) (T_LIN holds the ripples and the startup
        # growth, eq. H4), speed eq. (11)
        lvl = _level(w, a_in, j, w_m, _g(w, T_LIN, j)) + 0.0
        lvl = (lvl if lvl > 0.0 else 0.0) + g_m * lvl_t
        w_m_new, pm = _advance(w_m, t_m - t_k * gear, _g(w, H_M, j),
                               _visc(w, a_in, j, w_m) + g_m * g_m * vis_t, lvl)
        # --- output side: speed eq. (11)
        t_load = _g(w, LOAD0, j) + _g(w, TEXT, j)
        t_load = t_load + _g(w, GRAV, j) * _g(w, SIN + P_GRAV, j)
        lvl = 0.0 if mesh else lvl_t
        w_o_new, po = _advance(w_o, t_k - t_load, _g(w, H_O, j), 0.0 if mesh else vis_t, lvl)
        locked = _g(w, LOCK, j) != 0.0
        w_o_new = 0.0 if locked else w_o_new
        po = 0.0 if locked else po
        _s(w, L.T_LOAD, j, t_load)
        # eq. (8), placement splines: the sensor reads J_o dw_o/dt + T_load
        t_s = (w_o_new - w_o) * _g(w, JO_DT, j) + t_load
        _s(w, L.TK, j, t_s if _g(w, SENSE, j) != 0.0 else t_k)
        # --- angles eq. (12) and bookkeeping eq. (13)
        dt = _g(w, DT, j)
        d_m = dt * w_m_new
        d_o = dt * w_o_new
        _s(w, T_DM, j, d_m)
        _s(w, T_DO, j, d_o)
        _s(w, L.W_M, j, w_m_new)
        _s(w, L.W_O, j, w_o_new)
        _s(w, L.TH_M, j, _g(w, L.TH_M, j) + d_m)
        _s(w, L.TH_O, j, _g(w, L.TH_O, j) + d_o)
        ddth = _g(w, T_DDTH, j)
        _s(w, L.E_DISS, j, _g(w, L.E_DISS, j)
           + (dt * (pm + po + _g(w, CDAMP, j) * ddth * ddth) + _g(w, T_DISS, j)))
        _s(w, L.W_MOTOR, j, _g(w, L.W_MOTOR, j) + dt * t_m * w_m_new)
        _s(w, L.W_LOAD, j, _g(w, L.W_LOAD, j) - dt * t_load * w_o_new)


@inline_lane
def _phases(w: np.ndarray, nl: int, nke: int, nrin: int, nrout: int, grav: bool) -> None:
    """Rotate every phase by its angle's increment over the substep (the phases of eq. (1)
    and of the ripple term of eq. (7))."""
    for k in range(nke):
        for j in range(nl):
            _s(w, T_D, j, _g(w, KE_O + k, j) * _g(w, T_DM, j))
        _rotate(w, nl, P_KE + k)
    for side in range(2):
        at = SIDE[side]
        for k in range(nrin if side == 0 else nrout):
            for j in range(nl):
                d_o = _g(w, T_DO, j)
                d_m = _g(w, T_DM, j)
                inc = d_o if _g(w, at + F_RF + k, j) != 0.0 else d_m
                _s(w, T_D, j, _g(w, at + F_RO + k, j) * inc)
            _rotate(w, nl, P_RIP[side] + k)
    if grav:
        for j in range(nl):
            _s(w, T_D, j, _g(w, T_DO, j))
        _rotate(w, nl, P_GRAV)


@jit_lane
def _bad_lane(w: np.ndarray, j: int) -> bool:
    for k in range(L.N_STATE):
        if not math.isfinite(_g(w, k, j)):
            return True
    return abs(_g(w, L.W_M, j)) > 1e7 or abs(_g(w, L.TK, j)) > 1e9


@jit_lane
def run_block(w: np.ndarray, nl: int, n_sub: int) -> None:
    """``n_sub`` substeps for the first ``nl`` lanes of block buffer ``w``."""
    # nl <= BLOCK, stated so the compiler can prove the fields never overlap
    nl = min(nl, BLOCK)
    for j in range(nl):
        if _g(w, COUNT, j) >= RESYNC:
            sync_lane(w, j)
    nke = _block_max(w, nl, NKE)
    nslip = _block_max(w, nl, NSLIP)
    nrin = _block_max(w, nl, NRIP_IN)
    nrout = _block_max(w, nl, NRIP_OUT)
    any_tanh = _block_max(w, nl, TANH) > 0
    grav = False
    for j in range(nl):
        grav = grav or _g(w, GRAV, j) != 0.0
    for _ in range(n_sub):
        _torsion(w, nl, nke)
        _maxwell(w, nl, nslip)
        _ripple_sums(w, nl, nrin, nrout)
        if any_tanh:  # after the ripple sums: it adds the startup growth to the input's
            _tanh_hysteresis(w, nl)
        _drive_and_move(w, nl)
        _phases(w, nl, nke, nrin, nrout, grav)
    for j in range(nl):
        _s(w, COUNT, j, _g(w, COUNT, j) + n_sub)
        _s(w, BAD, j, 1.0 if _bad_lane(w, j) else 0.0)
