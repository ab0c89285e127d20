"""Flat array layouts of the physics state and parameters.

The compiled step works on one float64 row of state and one of parameters
per environment, so a batch is two 2-D arrays and every environment can
carry its own (randomized) drive. This module owns the column indices and
turns :class:`~hdgym.params.JointParams` into a parameter row.
"""

from __future__ import annotations

import numpy as np

from hdgym.effects import BIT
from hdgym.params import MAX_HARMONICS, MAX_RIPPLES, MAX_SLIP_ELEMENTS, FrictionSide, JointParams

# ------------------------------------------------------------------ state
TH_M = 0  # motor (WG) angle relative to the grounded port, rad
W_M = 1  # motor speed, rad/s
TH_O = 2  # output angle, rad (ideal: TH_M / ratio)
W_O = 3  # output speed, rad/s
CUR = 4  # motor current, A
TK = 5  # transmitted (flexspline) torque, output N m
DTH = 6  # torsion at the last substep, output rad
E_DISS = 7  # energy dissipated so far, J
W_MOTOR = 8  # work done by the motor torque, J
W_LOAD = 9  # work done on the joint by the external load, J
T_LOAD = 10  # external load torque last applied, N m (resists positive motion)
T_MOTOR = 11  # motor torque last applied, N m
HZ = 12  # hysteresis memory: Maxwell-slip forces, or tanh (phi*, dT*, s, T_h, load history L,
#         virgin: 1 until the first reversal, docs/physics.md eq. H1)
N_STATE = HZ + MAX_SLIP_ELEMENTS

STATE_NAMES = (
    "motor_angle", "motor_velocity", "output_angle", "output_velocity", "motor_current",
    "output_torque", "torsion", "energy_dissipated", "work_motor", "work_load",
    "load_torque", "motor_torque",
) + tuple(f"hysteresis_{k}" for k in range(MAX_SLIP_ELEMENTS))

# ------------------------------------------------------------------ parameters
_names: list[str] = []


def _col(name: str, n: int = 1) -> int:
    start = len(_names)
    _names.extend([name] if n == 1 else [f"{name}[{k}]" for k in range(n)])
    return start


J_M = _col("motor.inertia")
KT = _col("motor.torque_constant")
KB = _col("motor.back_emf_constant")
RES = _col("motor.resistance")
RATIO = _col("transmission.ratio")
J_O = _col("load.inertia")
LOAD_T = _col("load.torque")
GRAV = _col("load.gravity")
K1 = _col("compliance.stiffness")
K3 = _col("compliance.cubic")
KNEE = _col("compliance.knee")
K0 = _col("compliance.extra_stiffness")
ST1 = _col("compliance.segment_torques[0]")
ST2 = _col("compliance.segment_torques[1]")
SK2 = _col("compliance.segment_stiffness[0]")
SK3 = _col("compliance.segment_stiffness[1]")
CDAMP = _col("compliance.damping")
CMODEL = _col("compliance.model")  # 0 linear, 1 cubic, 2 two_segment, 3 three_segment
HMODEL = _col("hysteresis.model")  # 0 maxwell, 1 tanh
NSLIP = _col("hysteresis.n_elements")
SLIP_K = _col("hysteresis.element_stiffness", MAX_SLIP_ELEMENTS)
SLIP_W = _col("hysteresis.element_strength", MAX_SLIP_ELEMENTS)
TANH_B = _col("hysteresis.width")
TANH_G = _col("hysteresis.shape")
TANH_B1 = _col("hysteresis.width_slope")
TANH_G1 = _col("hysteresis.shape_slope")
STARTUP1 = _col("hysteresis.startup_slope")
MU_LOAD = _col("friction.load_coefficient")
MESH = _col("friction.placement")  # 0 output (to ground), 1 mesh (FS-CS, seen by the WG),
#                                     2 splines (FS-CS on the output side of the spring)
NKE = _col("kinematic_error.n_harmonics")
KE_ORD = _col("kinematic_error.order", MAX_HARMONICS)  # effective order of the WG angle
KE_AMP = _col("kinematic_error.amplitude", MAX_HARMONICS)
KE_PH = _col("kinematic_error.phase", MAX_HARMONICS)
I_MAX = _col("amplifier.current_limit")
V_MAX = _col("amplifier.voltage_limit")
BW = _col("amplifier.bandwidth")

# friction sides share one sub-layout at two offsets
F_FC = 0
F_FS = 1
F_WS = 2
F_B1 = 3
F_B2 = 4
F_NRIP = 5
F_RORD = 6
F_RFRAME = F_RORD + MAX_RIPPLES  # 0 input angle, 1 output angle
F_RAMP = F_RFRAME + MAX_RIPPLES
F_RPH = F_RAMP + MAX_RIPPLES
F_SIZE = F_RPH + MAX_RIPPLES
_SIDE_FIELDS = ("coulomb", "breakaway", "stribeck_velocity", "viscous", "cubic", "n_ripple")


def _side(prefix: str) -> int:
    start = len(_names)
    _names.extend(f"{prefix}.{f}" for f in _SIDE_FIELDS)
    for what in ("order", "frame", "amplitude", "phase"):
        _names.extend(f"{prefix}.ripple[{k}].{what}" for k in range(MAX_RIPPLES))
    assert len(_names) - start == F_SIZE
    return start


FIN = _side("friction.input")
FOUT = _side("friction.output")
N_PARAMS = len(_names)
PARAM_NAMES: tuple[str, ...] = tuple(_names)
PARAM_INDEX: dict[str, int] = {n: k for k, n in enumerate(PARAM_NAMES)}

_CMODELS = {"linear": 0, "cubic": 1, "two_segment": 2, "three_segment": 3}
_HMODELS = {"maxwell": 0, "tanh": 1}
#: friction.placement -> the MESH column (docs/physics.md eq. 8)
PLACEMENT_CODES = {"output": 0.0, "mesh": 1.0, "splines": 2.0}


def _pack_side(row: np.ndarray, base: int, side: FrictionSide) -> None:
    row[base + F_FC] = side.coulomb
    row[base + F_FS] = side.breakaway
    row[base + F_WS] = side.stribeck_velocity
    row[base + F_B1] = side.viscous
    row[base + F_B2] = side.cubic
    row[base + F_NRIP] = len(side.ripple)
    for k, r in enumerate(side.ripple):
        row[base + F_RORD + k] = r.order
        row[base + F_RFRAME + k] = 0.0 if r.frame == "input" else 1.0
        row[base + F_RAMP + k] = r.amplitude
        row[base + F_RPH + k] = r.phase


def pack(p: JointParams) -> np.ndarray:
    """One parameter row (float64, length :data:`N_PARAMS`) for ``p``."""
    row = np.zeros(N_PARAMS)
    row[J_M] = p.motor.inertia
    row[KT] = p.motor.torque_constant
    row[KB] = p.motor.back_emf_constant
    row[RES] = p.motor.resistance
    row[RATIO] = p.transmission.ratio
    row[J_O] = p.load.inertia
    row[LOAD_T] = p.load.torque
    row[GRAV] = p.load.gravity
    c = p.compliance
    row[K1] = c.stiffness
    row[K3] = c.cubic
    row[KNEE] = c.knee
    row[K0] = c.extra_stiffness
    row[ST1], row[ST2] = c.segment_torques
    row[SK2], row[SK3] = c.segment_stiffness
    row[CDAMP] = c.damping
    row[CMODEL] = _CMODELS[c.model]
    h = p.hysteresis
    row[HMODEL] = _HMODELS[h.model]
    row[NSLIP] = len(h.element_stiffness)
    for k, (kappa, w) in enumerate(zip(h.element_stiffness, h.element_strength, strict=True)):
        row[SLIP_K + k] = kappa
        row[SLIP_W + k] = w
    row[TANH_B] = h.width
    row[TANH_G] = h.shape
    row[TANH_B1] = h.width_slope
    row[TANH_G1] = h.shape_slope
    row[STARTUP1] = h.startup_slope
    row[MU_LOAD] = p.friction.load_coefficient
    row[MESH] = PLACEMENT_CODES[p.friction.placement]
    _pack_side(row, FIN, p.friction.input)
    _pack_side(row, FOUT, p.friction.output)
    ke = p.kinematic_error.harmonics
    row[NKE] = len(ke)
    for k, hm in enumerate(ke):
        row[KE_ORD + k] = hm.order * p.transmission.port_factor(hm.port)
        row[KE_AMP + k] = hm.amplitude
        row[KE_PH + k] = hm.phase
    row[I_MAX] = p.amplifier.current_limit
    row[V_MAX] = p.amplifier.voltage_limit
    row[BW] = p.amplifier.bandwidth
    return row


def pack_batch(params: list[JointParams] | JointParams, n: int | None = None) -> np.ndarray:
    """Parameter rows ``(n_envs, N_PARAMS)`` for a list of joints, or ``n`` copies of one."""
    if isinstance(params, JointParams):
        return np.tile(pack(params), (1 if n is None else n, 1))
    return np.stack([pack(p) for p in params])


def kinematic_error(theta_m: np.ndarray, row: np.ndarray) -> np.ndarray:
    """theta_ke(theta_wg) in output rad for one parameter row (numpy)."""
    theta_m = np.asarray(theta_m, dtype=float)
    out = np.zeros_like(theta_m)
    for k in range(int(row[NKE])):
        out += row[KE_AMP + k] * np.sin(row[KE_ORD + k] * theta_m + row[KE_PH + k])
    return out


def initial_state(rows: np.ndarray, flags: np.ndarray | int,
                  motor_angle: np.ndarray | float = 0.0,
                  output_angle: np.ndarray | float | None = None) -> np.ndarray:
    """A state batch at rest with the given angles.

    With ``output_angle`` None the output sits where the spring is relaxed
    (``motor_angle/ratio - theta_ke``), so the joint starts without torque.
    """
    rows = np.atleast_2d(rows)
    n = rows.shape[0]
    x = np.zeros((n, N_STATE))
    th_m = np.broadcast_to(np.asarray(motor_angle, dtype=float), (n,)).copy()
    ke_on = (np.broadcast_to(np.asarray(flags, dtype=np.int64), (n,)) & BIT["kinematic_error"]) != 0
    ke = np.array([kinematic_error(th_m[e], rows[e]) if ke_on[e] else 0.0 for e in range(n)])
    if output_angle is None:
        th_o = th_m / rows[:, RATIO] - ke
    else:
        th_o = np.broadcast_to(np.asarray(output_angle, dtype=float), (n,)).copy()
    x[:, TH_M] = th_m
    x[:, TH_O] = th_o
    x[:, DTH] = th_m / rows[:, RATIO] - th_o - ke
    # tanh: the branch starts here, in no direction yet, on the virgin curve (eq. H1)
    x[:, HZ] = np.where(rows[:, HMODEL] == 1, x[:, DTH], 0.0)
    x[:, HZ + 5] = np.where(rows[:, HMODEL] == 1, 1.0, 0.0)
    return x

