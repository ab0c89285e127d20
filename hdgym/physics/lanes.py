"""The compiled joint step laid out for SIMD: many envs, one vector lane each.

:mod:`hdgym.physics.kernel` steps one env at a time; each substep there is
one long chain of dependent operations, so a core mostly waits on
latencies. Here envs are grouped in blocks of :data:`BLOCK`, and every
substep is a handful of passes over a block, each pass a branch-free loop
over its envs that the compiler turns into vector instructions (8 envs per
instruction with AVX-512, 4 with AVX2). The physics is the kernel's
semi-implicit step, operation for operation; the tests hold both to the
numpy reference (:mod:`hdgym.physics.reference`). The one-env kernel stays
for single trajectories, where a block would run 63 spare lanes.

A block is one flat float64 buffer of :data:`N_FIELDS` fields per env: the
state (layout of :mod:`hdgym.physics.layout`), constants derived once from
the parameter row, the effect flags and the substep (reciprocals, limits;
effects that are off become zero amplitudes or infinite limits, so every
lane runs the same instructions), sin and cos of the kinematic-error,
friction-ripple and gravity phases, and the substep's temporaries. The
phases are rotated by each substep's angle increment (a Taylor series; exact
sin/cos for increments of 0.3 rad and more) and recomputed exactly every
:data:`RESYNC` substeps.

:class:`LaneBatch` owns the buffers and mirrors the state into the caller's
``(n, N_STATE)`` rows after every step; after writing rows (a reset), call
:meth:`LaneBatch.load`.
"""


from __future__ import annotations

import math

import numba as nb
import numpy as np

from hdgym.params import MAX_HARMONICS, MAX_RIPPLES, MAX_SLIP_ELEMENTS
from hdgym.physics import layout as L
from hdgym.physics.kernel import (
    AMP,
    COUL,
    HYST,
    KE,
    LOADDEP,
    LOCKED,
    NONLIN,
    POSDEP,
    REVERSAL_DEADBAND,
    STICK,
    STRIB,
    sincos_small,
    viscous_constants,
)

# error_model="numpy": a division by zero in a lane whose result is discarded
# must not raise (it would also stop the loop from vectorizing). The passes are
# inlined into the block loop: a call per pass would cost reference counting.
_jit = nb.njit(cache=True, fastmath={"contract"}, nogil=True, error_model="numpy")
_inl = nb.njit(cache=True, fastmath={"contract"}, nogil=True, error_model="numpy",
               inline="always")

# ------------------------------------------------------------------ fields
# A block buffer ``w`` holds BLOCK envs: field ``f`` of lane ``j`` is
# ``w[f * BLOCK + j]``. With BLOCK a compile-time constant, the compiler can
# see that different fields never overlap, which is what lets it vectorize.
# State fields keep the indices of :mod:`hdgym.physics.layout`; constants,
# phases, temporaries and inputs follow.
_n = L.N_STATE


def _rows(count: int = 1) -> int:
    global _n
    start = _n
    _n += count
    return start


#: envs per block (a multiple of the widest vector, 8 doubles)
BLOCK = 64
DT = _rows()
INV_R = _rows()
H_M = _rows()  # substep / motor inertia
H_O = _rows()  # substep / output inertia (0 when the output is locked)
LOCK = _rows()  # 1 when the output is locked
ALPHA = _rows()  # current-loop step factor
IMAX = _rows()
VHI = _rows()  # V_max / R
KBR = _rows()  # K_b / R
KT = _rows()
CDAMP = _rows()
GRAV = _rows()
LOAD0 = _rows()
MU = _rows()
K1 = _rows()
K3 = _rows()
CMODEL = _rows()  # 0 linear, 1 cubic, 2 two-segment, 3 three-segment
KNEE = _rows()
K0 = _rows()
TH1 = _rows()
TH2 = _rows()
ST1 = _rows()
ST2 = _rows()
SK2 = _rows()
SK3 = _rows()
TANH = _rows()  # 1 for the tanh hysteresis model
TANH_B = _rows()
TANH_G = _rows()
NKE = _rows()
NSLIP = _rows()  # Maxwell-slip elements in use (0 with the tanh model)
NRIP_IN = _rows()
NRIP_OUT = _rows()
KE_A = _rows(MAX_HARMONICS)  # amplitude
KE_AO = _rows(MAX_HARMONICS)  # amplitude * order
KE_O = _rows(MAX_HARMONICS)  # order
KE_PH = _rows(MAX_HARMONICS)  # phase
SLIP_K = _rows(MAX_SLIP_ELEMENTS)
SLIP_W = _rows(MAX_SLIP_ELEMENTS)
SLIP_WK = _rows(MAX_SLIP_ELEMENTS)  # strength / stiffness (0 for a rigid element)
#: per friction side (input, output), offsets from SIDE[side]: Coulomb level,
#: level when stuck, Stribeck on, breakaway, Stribeck speed, viscous b1, b2,
#: peak speed^2, peak torque, then ripple amplitudes, orders, frames, phases
F_FC, F_STUCK, F_STRIB, F_FS, F_WS, F_B1, F_B2, F_PK2, F_FPK = range(9)
F_RA = 9
F_RO = F_RA + MAX_RIPPLES
F_RF = F_RO + MAX_RIPPLES  # 0 input angle, 1 output angle
F_RPH = F_RF + MAX_RIPPLES
F_N = F_RPH + MAX_RIPPLES
SIDE = (_rows(F_N), _rows(F_N))
#: phases: kinematic-error harmonics, input ripples, output ripples, gravity arm;
#: sines at SIN + phase, cosines at COS + phase
N_PHASES = MAX_HARMONICS + 2 * MAX_RIPPLES + 1
P_KE = 0
P_RIP = (MAX_HARMONICS, MAX_HARMONICS + MAX_RIPPLES)
P_GRAV = N_PHASES - 1
SIN = _rows(N_PHASES)
COS = _rows(N_PHASES)
COUNT = _rows()  # substeps since the phases were last computed exactly
ICMD = _rows()  # inputs of the call
TEXT = _rows()
BAD = _rows()
# temporaries of one substep
(T_KE, T_DKE, T_DTH, T_GEAR, T_DDTH, T_DINC, T_TH, T_DISS, T_LIN, T_LOUT, T_DM, T_DO,
 T_D) = (_rows() for _ in range(13))
#: fields per env
N_FIELDS = _n
#: substeps between exact recomputations of the rotated phases
RESYNC = 10_000


@_inl
def _g(w: np.ndarray, f: int, j: int) -> float:
    # unsigned index: no negative-index wraparound, which would hide the access
    # pattern from the vectorizer
    return w[np.uint64(f * BLOCK + j)]


@_inl
def _s(w: np.ndarray, f: int, j: int, v: float) -> None:
    w[np.uint64(f * BLOCK + j)] = v


@_jit
def _prepare_lane(p: np.ndarray, flags: int, dt: float, w: np.ndarray, j: int) -> None:
    """Derived constants of one env (parameter row ``p``) into lane ``j`` of block ``w``."""
    _s(w, DT, j, dt)
    _s(w, INV_R, j, 1.0 / p[L.RATIO])
    _s(w, H_M, j, dt / p[L.J_M])
    locked = (flags & LOCKED) != 0
    _s(w, LOCK, j, 1.0 if locked else 0.0)
    _s(w, H_O, j, 0.0 if locked else dt / p[L.J_O])
    _s(w, ALPHA, j, 1.0 - math.exp(-2.0 * math.pi * p[L.BW] * dt))
    if flags & AMP:
        inv_res = 1.0 / p[L.RES]
        _s(w, IMAX, j, p[L.I_MAX])
        _s(w, VHI, j, p[L.V_MAX] * inv_res)
        _s(w, KBR, j, p[L.KB] * inv_res)
    else:
        _s(w, IMAX, j, np.inf)
        _s(w, VHI, j, np.inf)
        _s(w, KBR, j, 0.0)
    _s(w, KT, j, p[L.KT])
    _s(w, CDAMP, j, p[L.CDAMP])
    _s(w, GRAV, j, p[L.GRAV])
    _s(w, LOAD0, j, p[L.LOAD_T])
    _s(w, MU, j, p[L.MU_LOAD] if (flags & LOADDEP) else 0.0)
    k1 = p[L.K1]
    _s(w, K1, j, k1)
    _s(w, CMODEL, j, p[L.CMODEL] if (flags & NONLIN) else 0.0)
    _s(w, K3, j, p[L.K3])
    _s(w, KNEE, j, p[L.KNEE])
    _s(w, K0, j, p[L.K0])
    th1 = p[L.ST1] / k1 if k1 != 0.0 else 0.0
    _s(w, TH1, j, th1)
    _s(w, TH2, j, th1 + (p[L.ST2] - p[L.ST1]) / p[L.SK2] if p[L.SK2] != 0.0 else th1)
    _s(w, ST1, j, p[L.ST1])
    _s(w, ST2, j, p[L.ST2])
    _s(w, SK2, j, p[L.SK2])
    _s(w, SK3, j, p[L.SK3])
    hyst = (flags & HYST) != 0
    tanh_model = hyst and p[L.HMODEL] == 1.0
    _s(w, TANH, j, 1.0 if tanh_model else 0.0)
    _s(w, TANH_B, j, p[L.TANH_B])
    _s(w, TANH_G, j, p[L.TANH_G])
    nslip = int(p[L.NSLIP]) if (hyst and not tanh_model) else 0
    _s(w, NSLIP, j, nslip)
    for k in range(MAX_SLIP_ELEMENTS):
        _s(w, SLIP_K + k, j, p[L.SLIP_K + k] if k < nslip else 0.0)
        _s(w, SLIP_W + k, j, p[L.SLIP_W + k] if k < nslip else 0.0)
        kap = p[L.SLIP_K + k]
        _s(w, SLIP_WK + k, j, p[L.SLIP_W + k] / kap if (k < nslip and kap > 0.0) else 0.0)
    nke = int(p[L.NKE]) if (flags & KE) else 0
    _s(w, NKE, j, nke)
    for k in range(MAX_HARMONICS):
        on = k < nke
        _s(w, KE_A + k, j, p[L.KE_AMP + k] if on else 0.0)
        _s(w, KE_AO + k, j, p[L.KE_AMP + k] * p[L.KE_ORD + k] if on else 0.0)
        _s(w, KE_O + k, j, p[L.KE_ORD + k] if on else 0.0)
        _s(w, KE_PH + k, j, p[L.KE_PH + k] if on else 0.0)
    coul = (flags & COUL) != 0
    for side in range(2):
        base = L.FIN if side == 0 else L.FOUT
        at = SIDE[side]
        fc = p[base + L.F_FC]
        _s(w, at + F_FC, j, fc if coul else 0.0)
        stuck = p[base + L.F_FS] if (flags & (STICK | STRIB)) else fc
        _s(w, at + F_STUCK, j, stuck if coul else 0.0)
        _s(w, at + F_STRIB, j, 1.0 if (coul and (flags & STRIB)) else 0.0)
        _s(w, at + F_FS, j, p[base + L.F_FS])
        _s(w, at + F_WS, j, p[base + L.F_WS])
        mode, b1, b2, pk2, fpk = viscous_constants(p, base, flags)
        _s(w, at + F_B1, j, b1)
        _s(w, at + F_B2, j, b2)
        _s(w, at + F_PK2, j, pk2 if mode == 3 else np.inf)  # only mode 3 is capped
        _s(w, at + F_FPK, j, fpk)
        nrip = int(p[base + L.F_NRIP]) if (flags & POSDEP) else 0
        _s(w, NRIP_IN if side == 0 else NRIP_OUT, j, nrip)
        for k in range(MAX_RIPPLES):
            on = k < nrip
            _s(w, at + F_RA + k, j, p[base + L.F_RAMP + k] if on else 0.0)
            _s(w, at + F_RO + k, j, p[base + L.F_RORD + k] if on else 0.0)
            _s(w, at + F_RF + k, j, p[base + L.F_RFRAME + k] if on else 0.0)
            _s(w, at + F_RPH + k, j, p[base + L.F_RPH + k] if on else 0.0)


@_jit
def _set_phase(w: np.ndarray, ph: int, j: int, a: float) -> None:
    _s(w, SIN + ph, j, math.sin(a))
    _s(w, COS + ph, j, math.cos(a))


@_jit
def _sync_lane(w: np.ndarray, j: int) -> None:
    """Exact phases of lane ``j`` at its current angles."""
    th_m = _g(w, L.TH_M, j)
    th_o = _g(w, L.TH_O, j)
    for ph in range(N_PHASES):
        _s(w, SIN + ph, j, 0.0)
        _s(w, COS + ph, j, 1.0)
    for k in range(int(_g(w, NKE, j))):
        _set_phase(w, P_KE + k, j, _g(w, KE_O + k, j) * th_m + _g(w, KE_PH + k, j))
    for side in range(2):
        at = SIDE[side]
        for k in range(int(_g(w, NRIP_IN if side == 0 else NRIP_OUT, j))):
            ang = th_m if _g(w, at + F_RF + k, j) == 0.0 else th_o
            _set_phase(w, P_RIP[side] + k, j, _g(w, at + F_RO + k, j) * ang
                       + _g(w, at + F_RPH + k, j))
    if _g(w, GRAV, j) != 0.0:
        _set_phase(w, P_GRAV, j, th_o)
    _s(w, COUNT, j, 0.0)


@_inl
def _sincos_tiny(d: float) -> tuple[float, float]:
    """sin and cos of |d| < 0.05 (Taylor to d^9 / d^10: truncation below 2e-22)."""
    z = d * d
    sd = d * (1.0 + z * (-1.0 / 6.0 + z * (1.0 / 120.0 + z * (
        -1.0 / 5040.0 + z / 362880.0))))
    cd = 1.0 + z * (-0.5 + z * (1.0 / 24.0 + z * (-1.0 / 720.0 + z * (
        1.0 / 40320.0 - z / 3628800.0))))
    return sd, cd


@_inl
def _turn(w: np.ndarray, ph: int, j: int, sd: float, cd: float) -> None:
    """Rotate phase ``ph`` of lane ``j`` by the angle whose sine and cosine are given."""
    s = _g(w, SIN + ph, j)
    c = _g(w, COS + ph, j)
    _s(w, SIN + ph, j, s * cd + c * sd)
    _s(w, COS + ph, j, c * cd - s * sd)


@_inl
def _rotate(w: np.ndarray, nl: int, ph: int) -> None:
    """Rotate phase ``ph`` of every lane by its increment in field T_D."""
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
    elif big == 0:
        for j in range(nl):
            sd, cd = sincos_small(_g(w, T_D, j))
            _turn(w, ph, j, sd, cd)
    else:
        for j in range(nl):  # coarse substeps or very fast motors
            d = _g(w, T_D, j)
            if abs(d) < 0.3:
                sd, cd = sincos_small(d)
            else:
                sd = math.sin(d)
                cd = math.cos(d)
            _turn(w, ph, j, sd, cd)


@_inl
def _spring(w: np.ndarray, j: int, x: float) -> float:
    """Spring torque, branch-free form of :func:`hdgym.physics.kernel.spring_torque`."""
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


@_inl
def _advance(v0: float, tau: float, h: float, visc: float, level: float) -> tuple[float, float]:
    """New speed and dissipated power, branch-free form of :func:`kernel._advance`."""
    inv = 1.0 / (1.0 + h * visc)
    v_free = (v0 + h * tau) * inv
    dv = h * level * inv
    stuck = abs(v_free) <= dv
    v = v_free - dv if v_free > 0.0 else v_free + dv
    v = 0.0 if stuck else v
    pw = 0.0 if stuck else visc * v * v + level * abs(v)
    return v, pw


@_inl
def _visc(w: np.ndarray, at: int, j: int, v: float) -> float:
    """Secant viscous coefficient (see :func:`kernel._viscous_coeff`)."""
    v2 = v * v
    below = _g(w, at + F_B1, j) + _g(w, at + F_B2, j) * v2
    capped = _g(w, at + F_FPK, j) / abs(v)
    return below if v2 <= _g(w, at + F_PK2, j) else capped


@_inl
def _block_max(w: np.ndarray, nl: int, f: int) -> int:
    m = 0.0
    for j in range(nl):
        m = max(m, _g(w, f, j))
    return int(m)


@_inl
def _tanh_hysteresis(w: np.ndarray, nl: int) -> None:
    """The tanh hysteresis model for the lanes that use it (scalar: it needs tanh)."""
    hz = L.HZ
    for j in range(nl):
        if _g(w, TANH, j) == 0.0:
            continue
        dth = _g(w, T_DTH, j)
        d_inc = _g(w, T_DINC, j)
        s = _g(w, hz + 2, j)
        if abs(d_inc) > REVERSAL_DEADBAND:
            s_new = 1.0 if d_inc > 0.0 else -1.0
            if s_new != s:  # reversal: remember where and how much
                _s(w, hz, j, dth - d_inc)
                _s(w, hz + 1, j, _g(w, hz + 3, j))
                _s(w, hz + 2, j, s_new)
                s = s_new
        dts = _g(w, hz + 1, j)
        t_h = dts + (s * _g(w, TANH_B, j) - dts) * math.tanh(
            _g(w, TANH_G, j) * s * (dth - _g(w, hz, j)))
        _s(w, hz + 3, j, t_h)
        _s(w, T_TH, j, t_h)


#: 2**-k for k = 0..63, for :func:`_exp_neg`
_POW2_NEG = np.array([2.0 ** -k for k in range(64)])
_LN2_HI = 6.93147180369123816490e-01  # ln 2 split so k * _LN2_HI is exact (fdlibm)
_LN2_LO = 1.90821492927058770002e-10


@_inl
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


@_inl
def _torsion(w: np.ndarray, nl: int, nke: int) -> None:
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


@_inl
def _maxwell(w: np.ndarray, nl: int, nslip: int) -> None:
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


@_inl
def _ripple_sums(w: np.ndarray, nl: int, nrin: int, nrout: int) -> None:
    """Position-dependent friction of each side, summed over its ripples, into T_LIN/T_LOUT."""
    for side in range(2):
        at = SIDE[side] + F_RA
        out = T_LIN if side == 0 else T_LOUT
        for j in range(nl):
            _s(w, out, j, 0.0)
        for k in range(nrin if side == 0 else nrout):
            for j in range(nl):
                _s(w, out, j, _g(w, out, j) + _g(w, at + k, j) * _g(w, SIN + P_RIP[side] + k, j))


@_inl
def _level(w: np.ndarray, at: int, j: int, v: float, ripple: float) -> float:
    """Coulomb-type level of one side at speed ``v`` (0: stuck) before the load term:
    Coulomb or breakaway, the Stribeck hump, plus the ripple sum."""
    fc = _g(w, at + F_FC, j)
    stuck = _g(w, at + F_STUCK, j)  # loaded before the select: a conditional load
    base = stuck if v == 0.0 else fc  # would keep the loop from vectorizing
    r = v / _g(w, at + F_WS, j)
    r2 = r * r
    # exp(-40) < 5e-18: the hump is gone far above the Stribeck speed
    on = _g(w, at + F_STRIB, j) != 0.0 and v != 0.0 and r2 < 40.0
    hump = fc + (_g(w, at + F_FS, j) - fc) * _exp_neg(r2 if r2 < 40.0 else 40.0)
    return (hump if on else base) + ripple


@_inl
def _drive_and_move(w: np.ndarray, nl: int) -> None:
    """Transmitted torque, amplifier and current loop, friction, new speeds and
    angles, energy bookkeeping: one pass, so the temporaries stay in registers."""
    a_in = SIDE[0]
    a_out = SIDE[1]
    for j in range(nl):
        # --- transmitted torque
        t_k = _spring(w, j, _g(w, T_DTH, j)) + _g(w, CDAMP, j) * _g(w, T_DDTH, j) \
            + _g(w, T_TH, j)
        _s(w, L.TK, j, t_k)
        # --- amplifier and current loop
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
        # --- motor side
        lvl = _level(w, a_in, j, w_m, _g(w, T_LIN, j)) + 0.0
        lvl = lvl if lvl > 0.0 else 0.0
        w_m_new, pm = _advance(w_m, t_m - t_k * _g(w, T_GEAR, j), _g(w, H_M, j),
                               _visc(w, a_in, j, w_m), lvl)
        # --- output side
        t_load = _g(w, LOAD0, j) + _g(w, TEXT, j)
        t_load = t_load + _g(w, GRAV, j) * _g(w, SIN + P_GRAV, j)
        lvl = _level(w, a_out, j, w_o, _g(w, T_LOUT, j)) + _g(w, MU, j) * abs(t_k)
        lvl = lvl if lvl > 0.0 else 0.0
        w_o_new, po = _advance(w_o, t_k - t_load, _g(w, H_O, j), _visc(w, a_out, j, w_o), lvl)
        locked = _g(w, LOCK, j) != 0.0
        w_o_new = 0.0 if locked else w_o_new
        po = 0.0 if locked else po
        _s(w, L.T_LOAD, j, t_load)
        # --- angles and bookkeeping
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


@_inl
def _phases(w: np.ndarray, nl: int, nke: int, nrin: int, nrout: int, grav: bool) -> None:
    """Rotate every phase by its angle's increment over the substep."""
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


@_jit
def _bad_lane(w: np.ndarray, j: int) -> bool:
    for k in range(L.N_STATE):
        if not math.isfinite(_g(w, k, j)):
            return True
    return abs(_g(w, L.W_M, j)) > 1e7 or abs(_g(w, L.TK, j)) > 1e9


@_jit
def run_block(w: np.ndarray, nl: int, n_sub: int) -> None:
    """``n_sub`` substeps for the first ``nl`` lanes of block buffer ``w``."""
    # nl <= BLOCK, stated so the compiler can prove the fields never overlap
    nl = min(nl, BLOCK)
    for j in range(nl):
        if _g(w, COUNT, j) >= RESYNC:
            _sync_lane(w, j)
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
        if any_tanh:
            _tanh_hysteresis(w, nl)
        _ripple_sums(w, nl, nrin, nrout)
        _drive_and_move(w, nl)
        _phases(w, nl, nke, nrin, nrout, grav)
    for j in range(nl):
        _s(w, COUNT, j, _g(w, COUNT, j) + n_sub)
        _s(w, BAD, j, 1.0 if _bad_lane(w, j) else 0.0)


# ------------------------------------------------------------------ batch
@_jit
def _load(W: np.ndarray, xs: np.ndarray, ps: np.ndarray, flags: np.ndarray, dt: float,
          idx: np.ndarray) -> None:
    for e in idx:
        w = W[e // BLOCK]
        j = e % BLOCK
        for f in range(L.N_STATE):
            _s(w, f, j, xs[e, f])
        _prepare_lane(ps[e], flags[e], dt, w, j)
        _sync_lane(w, j)


@_jit
def _step_block(W: np.ndarray, b: int, i_cmd: np.ndarray, t_ext: np.ndarray, n_sub: int,
                xs: np.ndarray, bad: np.ndarray) -> None:
    """Block ``b``: take its inputs, run it, and copy its state out to ``xs`` rows."""
    w = W[b]
    lo = b * BLOCK
    hi = min(xs.shape[0], lo + BLOCK)
    for e in range(lo, hi):
        _s(w, ICMD, e - lo, i_cmd[e])
        _s(w, TEXT, e - lo, t_ext[e])
    run_block(w, hi - lo, n_sub)
    for e in range(lo, hi):
        j = e - lo
        for f in range(L.N_STATE):
            xs[e, f] = _g(w, f, j)
        bad[e] = _g(w, BAD, j) != 0.0


@_jit
def _step_serial(W: np.ndarray, i_cmd: np.ndarray, t_ext: np.ndarray, n_sub: int,
                 xs: np.ndarray, bad: np.ndarray) -> None:
    for b in range(W.shape[0]):
        _step_block(W, b, i_cmd, t_ext, n_sub, xs, bad)


@nb.njit(cache=True, parallel=True, nogil=True)
def _step_parallel(W: np.ndarray, i_cmd: np.ndarray, t_ext: np.ndarray, n_sub: int,
                   xs: np.ndarray, bad: np.ndarray) -> None:
    for b in nb.prange(W.shape[0]):
        _step_block(W, b, i_cmd, t_ext, n_sub, xs, bad)


def _check(a: np.ndarray, shape: tuple[int, ...], name: str) -> None:
    # the compiled loops do not check bounds: a wrong shape would read past the end
    if not isinstance(a, np.ndarray) or a.shape != shape:
        raise ValueError(f"{name} must be an array of shape {shape}, got "
                         f"{getattr(a, 'shape', type(a).__name__)}")


#: batch size from which :class:`LaneBatch` spreads its blocks over the cores
#: (below it, starting the threads costs more than they save)
PARALLEL_THRESHOLD = 256


class LaneBatch:
    """``n`` joints in SIMD blocks; the state is mirrored into ``xs`` after every step.

    Args:
        xs: ``(n, N_STATE)`` state rows (read now, written after every step).
        ps: ``(n, N_PARAMS)`` parameter rows.
        flags: ``(n,)`` effect flags.
        dt: substep, s.
        parallel: spread blocks over the cores.
    """

    def __init__(self, xs: np.ndarray, ps: np.ndarray, flags: np.ndarray, dt: float,
                 parallel: bool = False) -> None:
        self.n = xs.shape[0]
        if not (dt > 0 and math.isfinite(dt)):
            raise ValueError(f"dt must be > 0 s, got {dt!r}")
        self.dt = float(dt)
        n_blocks = (self.n + BLOCK - 1) // BLOCK
        # the last block's spare lanes are never computed
        self.W = np.zeros((n_blocks, N_FIELDS * BLOCK))
        self.parallel = parallel
        self.load(xs, ps, flags, np.arange(self.n))

    def load(self, xs: np.ndarray, ps: np.ndarray, flags: np.ndarray, idx: np.ndarray) -> None:
        """Take state, parameters and flags of envs ``idx`` (after a reset or a change)."""
        n = self.n
        _check(xs, (n, L.N_STATE), "xs")
        _check(ps, (n, L.N_PARAMS), "ps")
        _check(flags, (n,), "flags")
        idx = np.asarray(idx, dtype=np.int64)
        if idx.size and (idx.min() < 0 or idx.max() >= n):
            raise ValueError(f"idx: env indices must be in [0, {n}), got {idx!r}")
        _load(self.W, xs, ps, flags.astype(np.int64, copy=False), self.dt, idx)

    def step(self, i_cmd: np.ndarray, t_ext: np.ndarray, n_sub: int, xs: np.ndarray,
             bad: np.ndarray) -> None:
        """One control period: ``n_sub`` substeps at currents ``i_cmd`` (A), external
        loads ``t_ext`` (N m); the new state goes to ``xs`` rows, divergence to ``bad``."""
        n = self.n
        _check(i_cmd, (n,), "i_cmd")
        _check(t_ext, (n,), "t_ext")
        _check(xs, (n, L.N_STATE), "xs")
        _check(bad, (n,), "bad")
        if int(n_sub) != n_sub or n_sub < 1:
            raise ValueError(f"n_sub must be a whole number >= 1, got {n_sub!r}")
        fn = _step_parallel if self.parallel else _step_serial
        fn(self.W, i_cmd, t_ext, n_sub, xs, bad)
