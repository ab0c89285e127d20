"""The block buffer of :mod:`hdgym.physics.lanes`: its fields, and how a lane is filled.

A block buffer ``w`` holds :data:`BLOCK` envs as one flat float64 array:
field ``f`` of lane ``j`` is ``w[f * BLOCK + j]``. The fields are the state
(layout of :mod:`hdgym.physics.layout`, same indices), constants derived
once from the parameter row (:func:`prepare_lane`: reciprocals, limits;
effects that are off become zero amplitudes or infinite limits, so every
lane runs the same instructions), sin and cos of the kinematic-error,
friction-ripple and gravity phases (:func:`sync_lane`), the inputs of a
call and the substep's temporaries. The step itself is
:mod:`hdgym.physics.lane_step`.
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
    STICK,
    STRIB,
    viscous_constants,
)

# error_model="numpy": a division by zero in a lane whose result is discarded must not
# raise (it would also stop the loop from vectorizing). No fused multiply-add contraction:
# the compiler may fuse a*b + c*d differently in the vector body and in the scalar
# remainder of a loop, which made an env's last bits depend on its place in the block
# (and on its block mates); plain IEEE operations give every lane the same result alone
# or batched, at about 4 % of the lanes' speed.
jit_lane = nb.njit(cache=True, nogil=True, error_model="numpy")
inline_lane = nb.njit(cache=True, nogil=True, error_model="numpy", inline="always")

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
MESH = _rows()  # 1: the output side's friction acts in the mesh (eq. 8)
SENSE = _rows()  # 1: the state's torque is the grounded spline's (placement splines, eq. 8)
JO_DT = _rows()  # output inertia / substep
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
TANH = _rows()  # 1 for the tanh hysteresis model (its memory runs with hysteresis off too)
TANH_ON = _rows()  # 1 when the tanh element's torque is on (hysteresis effect)
TANH_B = _rows()
TANH_G = _rows()
TANH_B1 = _rows()  # width growth per N m of load history
TANH_G1 = _rows()  # shape change per N m of load history
STARTUP = _rows()  # input Coulomb growth per N m of load history (0 unless tanh + load friction)
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


@inline_lane
def get(w: np.ndarray, f: int, j: int) -> float:
    """Field ``f`` of lane ``j`` of block ``w``."""
    # unsigned index: no negative-index wraparound, which would hide the access
    # pattern from the vectorizer
    return w[np.uint64(f * BLOCK + j)]


@inline_lane
def put(w: np.ndarray, f: int, j: int, v: float) -> None:
    """Set field ``f`` of lane ``j`` of block ``w`` to ``v``."""
    w[np.uint64(f * BLOCK + j)] = v


@jit_lane
def prepare_lane(p: np.ndarray, flags: int, dt: float, w: np.ndarray, j: int) -> None:
    """Derived constants of one env (parameter row ``p``) into lane ``j`` of block ``w``."""
    put(w, DT, j, dt)
    put(w, INV_R, j, 1.0 / p[L.RATIO])
    put(w, H_M, j, dt / p[L.J_M])
    locked = (flags & LOCKED) != 0
    put(w, LOCK, j, 1.0 if locked else 0.0)
    put(w, H_O, j, 0.0 if locked else dt / p[L.J_O])
    # eqs. (9), (10): the current loop factor and the amplifier limits
    put(w, ALPHA, j, 1.0 - math.exp(-2.0 * math.pi * p[L.BW] * dt))
    if flags & AMP:
        inv_res = 1.0 / p[L.RES]
        put(w, IMAX, j, p[L.I_MAX])
        put(w, VHI, j, p[L.V_MAX] * inv_res)
        put(w, KBR, j, p[L.KB] * inv_res)
    else:
        put(w, IMAX, j, np.inf)
        put(w, VHI, j, np.inf)
        put(w, KBR, j, 0.0)
    put(w, KT, j, p[L.KT])
    put(w, CDAMP, j, p[L.CDAMP])
    put(w, GRAV, j, p[L.GRAV])
    put(w, LOAD0, j, p[L.LOAD_T])
    put(w, MU, j, p[L.MU_LOAD] if (flags & LOADDEP) else 0.0)
    put(w, MESH, j, 1.0 if p[L.MESH] == 1.0 else 0.0)
    put(w, SENSE, j, 1.0 if (p[L.MESH] == 2.0 and not locked) else 0.0)
    put(w, JO_DT, j, p[L.J_O] / dt)
    k1 = p[L.K1]
    put(w, K1, j, k1)
    put(w, CMODEL, j, p[L.CMODEL] if (flags & NONLIN) else 0.0)
    put(w, K3, j, p[L.K3])
    put(w, KNEE, j, p[L.KNEE])
    put(w, K0, j, p[L.K0])
    th1 = p[L.ST1] / k1 if k1 != 0.0 else 0.0
    put(w, TH1, j, th1)
    put(w, TH2, j, th1 + (p[L.ST2] - p[L.ST1]) / p[L.SK2] if p[L.SK2] != 0.0 else th1)
    put(w, ST1, j, p[L.ST1])
    put(w, ST2, j, p[L.ST2])
    put(w, SK2, j, p[L.SK2])
    put(w, SK3, j, p[L.SK3])
    hyst = (flags & HYST) != 0
    tanh_model = p[L.HMODEL] == 1.0
    put(w, TANH, j, 1.0 if tanh_model else 0.0)
    put(w, TANH_ON, j, 1.0 if (tanh_model and hyst) else 0.0)
    put(w, TANH_B, j, p[L.TANH_B])
    put(w, TANH_G, j, p[L.TANH_G])
    put(w, TANH_B1, j, p[L.TANH_B1])
    put(w, TANH_G1, j, p[L.TANH_G1])
    put(w, STARTUP, j, p[L.STARTUP1] if (tanh_model and (flags & LOADDEP)) else 0.0)
    nslip = int(p[L.NSLIP]) if (hyst and not tanh_model) else 0
    put(w, NSLIP, j, nslip)
    for k in range(MAX_SLIP_ELEMENTS):
        put(w, SLIP_K + k, j, p[L.SLIP_K + k] if k < nslip else 0.0)
        put(w, SLIP_W + k, j, p[L.SLIP_W + k] if k < nslip else 0.0)
        kap = p[L.SLIP_K + k]
        put(w, SLIP_WK + k, j, p[L.SLIP_W + k] / kap if (k < nslip and kap > 0.0) else 0.0)
    nke = int(p[L.NKE]) if (flags & KE) else 0
    put(w, NKE, j, nke)
    for k in range(MAX_HARMONICS):
        on = k < nke
        put(w, KE_A + k, j, p[L.KE_AMP + k] if on else 0.0)
        put(w, KE_AO + k, j, p[L.KE_AMP + k] * p[L.KE_ORD + k] if on else 0.0)
        put(w, KE_O + k, j, p[L.KE_ORD + k] if on else 0.0)
        put(w, KE_PH + k, j, p[L.KE_PH + k] if on else 0.0)
    coul = (flags & COUL) != 0
    for side in range(2):
        base = L.FIN if side == 0 else L.FOUT
        at = SIDE[side]
        fc = p[base + L.F_FC]
        put(w, at + F_FC, j, fc if coul else 0.0)
        stuck = p[base + L.F_FS] if (flags & (STICK | STRIB)) else fc
        put(w, at + F_STUCK, j, stuck if coul else 0.0)
        put(w, at + F_STRIB, j, 1.0 if (coul and (flags & STRIB)) else 0.0)
        put(w, at + F_FS, j, p[base + L.F_FS])
        put(w, at + F_WS, j, p[base + L.F_WS])
        mode, b1, b2, pk2, fpk = viscous_constants(p, base, flags)
        put(w, at + F_B1, j, b1)
        put(w, at + F_B2, j, b2)
        put(w, at + F_PK2, j, pk2 if mode == 3 else np.inf)  # only mode 3 is capped
        put(w, at + F_FPK, j, fpk)
        nrip = int(p[base + L.F_NRIP]) if (flags & POSDEP) else 0
        put(w, NRIP_IN if side == 0 else NRIP_OUT, j, nrip)
        for k in range(MAX_RIPPLES):
            on = k < nrip
            put(w, at + F_RA + k, j, p[base + L.F_RAMP + k] if on else 0.0)
            put(w, at + F_RO + k, j, p[base + L.F_RORD + k] if on else 0.0)
            put(w, at + F_RF + k, j, p[base + L.F_RFRAME + k] if on else 0.0)
            put(w, at + F_RPH + k, j, p[base + L.F_RPH + k] if on else 0.0)


@jit_lane
def _set_phase(w: np.ndarray, ph: int, j: int, a: float) -> None:
    put(w, SIN + ph, j, math.sin(a))
    put(w, COS + ph, j, math.cos(a))


@jit_lane
def sync_lane(w: np.ndarray, j: int) -> None:
    """Exact phases of lane ``j`` at its current angles."""
    th_m = get(w, L.TH_M, j)
    th_o = get(w, L.TH_O, j)
    for ph in range(N_PHASES):
        put(w, SIN + ph, j, 0.0)
        put(w, COS + ph, j, 1.0)
    for k in range(int(get(w, NKE, j))):
        _set_phase(w, P_KE + k, j, get(w, KE_O + k, j) * th_m + get(w, KE_PH + k, j))
    for side in range(2):
        at = SIDE[side]
        for k in range(int(get(w, NRIP_IN if side == 0 else NRIP_OUT, j))):
            ang = th_m if get(w, at + F_RF + k, j) == 0.0 else th_o
            _set_phase(w, P_RIP[side] + k, j, get(w, at + F_RO + k, j) * ang
                       + get(w, at + F_RPH + k, j))
    if get(w, GRAV, j) != 0.0:
        _set_phase(w, P_GRAV, j, th_o)
    put(w, COUNT, j, 0.0)
