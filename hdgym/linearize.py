"""Small-signal quantities of a joint, for linear control design.

The public face of the physics for code that designs linear controllers
(:mod:`controllers.tuning` builds its ``control.StateSpace`` from these): the
flexspline spring law and its slope, the torsion that carries a torque, the
small-signal torsional stiffness and the gear factor through the kinematic
error. Each evaluates the same compiled functions the simulator steps with,
so a linear model and a simulation never disagree on a parameter's meaning.
Callers need not know the packed parameter layout.
"""

from __future__ import annotations

import math

from hdgym.effects import flags_of
from hdgym.params import JointParams
from hdgym.physics import kernel
from hdgym.physics import layout as L

__all__ = ["gear_factor", "spring_slope", "spring_torque", "stiffness", "torsion_at", "viscous"]


def spring_torque(p: JointParams, torsion: float) -> float:
    """Flexspline spring torque at ``torsion`` (output rad), N m (the compliance law of ``p``)."""
    return kernel.spring_torque(torsion, L.pack(p), flags_of(p.effects))


def spring_slope(p: JointParams, torsion: float) -> float:
    """dT/d(torsion) of the flexspline spring at ``torsion`` (output rad), N m/rad."""
    row, flags = L.pack(p), flags_of(p.effects)
    h = max(1e-9, 1e-6 * abs(torsion))
    return (kernel.spring_torque(torsion + h, row, flags)
            - kernel.spring_torque(torsion - h, row, flags)) / (2 * h)


def torsion_at(p: JointParams, torque: float) -> float:
    """Torsion (output rad) at which the spring carries ``torque`` (N m); bisection."""
    row, flags = L.pack(p), flags_of(p.effects)
    if torque == 0:
        return 0.0
    lo, hi = 0.0, abs(torque) / p.compliance.stiffness * 2 + 1e-9
    s = math.copysign(1.0, torque)
    while abs(kernel.spring_torque(s * hi, row, flags)) < abs(torque):
        hi *= 2
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if abs(kernel.spring_torque(s * mid, row, flags)) < abs(torque):
            lo = mid
        else:
            hi = mid
    return s * 0.5 * (lo + hi)


def stiffness(p: JointParams, torque: float = 0.0, hysteresis: bool = True) -> float:
    """Small-signal torsional stiffness at the operating ``torque`` (N m), output N m/rad.

    The spring slope there, plus (``hysteresis`` and a Maxwell-slip model on)
    the stiffness of the stuck slip elements: small reversals do not slip them.
    """
    k = spring_slope(p, torsion_at(p, torque))
    if hysteresis and "hysteresis" in p.effects and p.hysteresis.model == "maxwell":
        k += sum(p.hysteresis.element_stiffness)
    return k


def gear_factor(p: JointParams, motor_angle: float = 0.0) -> float:
    """``d(theta_o)/d(theta_m)`` of the rigid gear at the WG angle ``motor_angle`` (rad).

    ``1/ratio - theta_ke'(motor_angle)``: the kinematic error's slope (output
    rad per WG rad; zero when the effect is off) changes the gear factor
    through which torsion and torque pass.
    """
    g = 1.0 / p.ratio
    if "kinematic_error" in p.effects:
        row = L.pack(p)
        for k in range(int(row[L.NKE])):
            n = row[L.KE_ORD + k]
            g -= row[L.KE_AMP + k] * n * math.cos(n * motor_angle + row[L.KE_PH + k])
    return g


def viscous(p: JointParams, motor_angle: float = 0.0) -> tuple[float, float]:
    """Linear viscous friction ``(b_motor, b_output)`` as the step applies it, N m s/rad.

    ``b_motor`` acts on the motor speed (motor-referred), ``b_output`` on the
    output speed (output-referred); both zero with ``viscous_friction`` off.
    With ``friction.placement = "mesh"`` the transmission's viscous friction
    acts at the mesh speed ``g w_m`` and reaches the motor as ``g^2 b``
    (docs/physics.md eq. 8), so the output carries none.
    """
    if "viscous_friction" not in p.effects:
        return 0.0, 0.0
    bm, bo = p.friction.input.viscous, p.friction.output.viscous
    if p.friction.placement == "mesh":
        g = gear_factor(p, motor_angle)
        return bm + g * g * bo, 0.0
    return bm, bo
