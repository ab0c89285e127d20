"""Gear effects of the registry: kinematic error, nonlinear stiffness, hysteresis, amplifier.

Each effect is four functions (fit parameters, switch-on values, neutral values; see
:class:`.effect.Effect`); :mod:`.registry` puts them together.
"""

from __future__ import annotations

import math

from hdgym.params import GROUNDED, JointParams

from .effect import (
    FREE,
    HIGH_TORQUE,
    MOVING,
    REVERSALS,
    SIMULATED,
    TE,
    TORSION,
    TURNS,
    TURNS_OR_REVISITS,
    Effect,
    FitParam,
)

KE_ORDERS = (1.0, 2.0, 4.0)
"""Orders of the kinematic-error lines, per WG revolution relative to the spline whose tooth
errors make them (docs/physics.md eq. (1): 2 dominant, then 4, sometimes 1)."""
KE_SPLIT = 0.5
"""Least phase, rad, by which the other spline's line must drift against the grounded one's
over a record for the two to be fitted apart (:func:`ke_lines`)."""
N_SLIP = 3


def ke_lines(p: JointParams, span: float) -> list[tuple[float, str, float]]:
    """Kinematic-error lines a record spanning ``span`` rad of WG angle can fit.

    Each order of :data:`KE_ORDERS` has two lines, as the simulator defines them
    (:meth:`hdgym.params.Transmission.port_factor`): the grounded spline's tooth
    errors at exactly that order of the WG angle, the other spline's at
    ``order x (1 -+ 1/ratio)`` (Tuttle's split lines; their beat has a period of
    about ratio / order WG turns). The other spline's line is kept only when it
    drifts at least :data:`KE_SPLIT` rad against the grounded one over the record;
    otherwise the grounded line alone stands for both.

    Returns:
        ``(order, port, effective order)`` per line.
    """
    tr = p.transmission
    other = next(g for g in GROUNDED if g != tr.grounded)
    out = []
    for o in KE_ORDERS:
        out.append((o, tr.grounded, o))
        eff = o * tr.port_factor(other)
        if abs(eff - o) * span >= KE_SPLIT:
            out.append((o, other, eff))
    return out


def _ke_params(p, s):
    a = max(3.0 * s.transmission_error, 1e-5)
    return [FitParam(f"kinematic_error.harmonics[{k}].{c}", -a, a)
            for k in range(len(p.kinematic_error.harmonics)) for c in ("sin", "cos")]


def _ke_on(p, s):
    lines = s.ke or tuple((o, p.transmission.grounded, 0.0, 0.0) for o in KE_ORDERS)
    out = [{"order": o, "amplitude": math.hypot(a, b), "phase": math.atan2(b, a), "port": port}
           for o, port, a, b in lines]
    return {"@kinematic_error.harmonics": out}


def _ke_neutral(d):
    d["kinematic_error"]["harmonics"] = []


def _hyst_params(p, s):
    h = p.hysteresis
    k1 = p.compliance.stiffness
    out = []
    for k in range(len(h.element_stiffness)):
        out.append(FitParam(f"hysteresis.element_stiffness[{k}]", 0.0, 3.0 * k1))
        out.append(FitParam(f"hysteresis.element_strength[{k}]", 0.0, 0.3 * s.torque))
    if h.model == "tanh":
        out = [FitParam("hysteresis.width", 0.0, 0.3 * s.torque),
               FitParam("hysteresis.shape", 0.0, 100.0 / max(s.torsion, 1e-9))]
    return out


def _hyst_on(p, s):
    k1 = p.compliance.stiffness
    kap = [k1 * f for f in (0.5, 0.2, 0.05)][:N_SLIP]
    strength = [s.torque * f for f in (0.005, 0.01, 0.02)][:N_SLIP]
    return {"@hysteresis": {"model": "maxwell", "element_stiffness": kap,
                            "element_strength": strength, "width": 0.0, "shape": 0.0}}


def _hyst_neutral(d):
    d["hysteresis"] = {"model": "maxwell", "element_stiffness": [], "element_strength": [],
                       "width": 0.0, "shape": 0.0}


def _nl_params(p, s):
    c = p.compliance
    k1 = c.stiffness
    x = max(s.torsion, 1e-9)
    if c.model == "two_segment":
        return [FitParam("compliance.knee", 0.0, 3.0 * x), FitParam("compliance.extra_stiffness",
                                                                     0.0, 3.0 * k1)]
    if c.model == "three_segment":
        return [FitParam("compliance.segment_stiffness[0]", 0.3 * k1, 5 * k1),
                FitParam("compliance.segment_stiffness[1]", 0.3 * k1, 10 * k1)]
    return [FitParam("compliance.cubic", 0.0, 20.0 * k1 / x**2)]


def _nl_on(p, s):
    c = p.compliance
    if c.model in ("two_segment", "three_segment"):
        return {}
    return {"@compliance.model": "cubic",
            "compliance.cubic": 0.05 * c.stiffness / max(s.torsion, 1e-9) ** 2}


def _nl_knee(p, s):
    """A hardening spring with a knee (two segments): stiffer by ``extra_stiffness`` above
    the torsion ``knee`` (the segmented springs of docs/physics.md, which a cubic bends
    through: the hold-out wave-drive-50 / nonlinear_stiffness, locked, seed 62)."""
    c = p.compliance
    return {"@compliance.model": "two_segment", "compliance.cubic": 0.0,
            "compliance.knee": 0.3 * max(s.torsion, 1e-9),
            "compliance.extra_stiffness": c.stiffness}


def _nl_neutral(d):
    c = d["compliance"]
    c["cubic"] = 0.0
    c["extra_stiffness"] = 0.0
    if c["model"] == "three_segment":
        c["model"] = "linear"
    if c["model"] in ("cubic", "two_segment"):
        c["model"] = "cubic"


def _amp_params(p, s):
    v = max(s.voltage, 1e-3)
    return [FitParam("amplifier.current_limit", 0.2 * s.current, 1.5 * s.current),
            FitParam("amplifier.voltage_limit", 0.2 * v, 3.0 * v)]


def _amp_on(p, s):
    """The limits at the record's clip levels. A voltage limit the record never reached
    starts at its range's top: at the largest voltage given it would clip any record that
    asks for more (development seed 206, tuttle-joint2 / amplifier_saturation /
    sine:5.85:2: 26 V given, the true limit 40 V; the validation record asks for 32 V and
    kept 37 % of its gap at the largest voltage given, none from the top; of the ten
    development sine cases of seeds 98-206, 9 hits at the largest voltage given, 10 from
    the top)."""
    cur = s.current_measured if s.current_measured > 0 else s.current
    v = max(s.voltage, 1e-3)
    return {"amplifier.current_limit": max(cur, 1e-6),
            "amplifier.voltage_limit": 3.0 * v if s.voltage_unreached else v}


def _amp_neutral(d):
    d["amplifier"]["current_limit"] = 1e6
    d["amplifier"]["voltage_limit"] = 1e9


GEAR_EFFECTS: tuple[Effect, ...] = (
    Effect("kinematic_error", "order_lines_te",
           "kinematic error: output lags/leads motor/ratio periodically in the WG angle",
           _ke_params, _ke_on, _ke_neutral, seen=(FREE, SIMULATED, TE, MOVING, TURNS_OR_REVISITS),
           # over a part turn its lines alias into each other and into any smooth function
           # of the angle (in a back-and-forth motion, of time): a given model's are refined
           # only within their tolerance (registry.TOLERANCE)
           refit=(TURNS,),
           channels="transmission_error against the WG angle", protocol="slow_constant_speed",
           compare=("time", "lines")),
    Effect("nonlinear_stiffness", "cubic_torsion",
           "hardening flexspline spring: residual cubic in the torsion",
           _nl_params, _nl_on, _nl_neutral, seen=(SIMULATED, TORSION, HIGH_TORQUE),
           channels="motor angle (locked) or transmission error against torque",
           protocol="locked_random", compare=("time", "spring"),
           forms=(("knee", _nl_knee),)),
    Effect("hysteresis", "torsion_loops",
           "hysteresis in the torsion: residual loops against torsion (Maxwell slip)",
           _hyst_params, _hyst_on, _hyst_neutral, seen=(SIMULATED, TORSION, REVERSALS),
           channels="torque against torsion, at reversals", protocol="locked_random",
           compare=("time", "spring")),
    Effect("amplifier_saturation", "clipped_current",
           "amplifier saturation: current clipped at the limit and by back-EMF at speed",
           _amp_params, _amp_on, _amp_neutral, seen=(SIMULATED, MOVING),
           channels="speed and current at large commands and high speed",
           protocol="current_steps"),
)
"""The gear's effects, in vocabulary order."""
