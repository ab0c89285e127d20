"""The effect registry shared by the simulator switches and the discrepancy workflow.

One :class:`Effect` per name of the vocabulary (:data:`hdgym.effects.EFFECTS`):

* how to switch it on: :meth:`Effect.switch_on` calls
  :meth:`JointParams.with_effects` (plus the effects it needs, e.g. Stribeck
  needs Coulomb friction) and sets the parameters it needs to a data-scaled
  initial guess, never to values hidden in the given parameter file;
* which parameters to fit (dotted paths), with bounds and initial guesses:
  :meth:`Effect.fit_params`;
* how to make it vanish while leaving the switch alone: :meth:`Effect.neutral`
  (used to build blind base models in the tests);
* its signature in the residuals: :attr:`Effect.signature` names a function
  in :data:`hdgym.discrepancy.residuals.SIGNATURES` (order lines of the WG
  angle, loops against torsion, binned speed dependence, sign-of-velocity
  steps, breakaway above running friction, dependence on transmitted torque,
  clipped current at speed, cubic residual against torsion).

Dotted paths extend :meth:`JointParams.get` with list items and two virtual
fields: ``kinematic_error.harmonics[0].sin`` / ``.cos`` are the coefficients
``a, b`` of ``a sin(n t) + b cos(n t)`` (amplitude ``hypot(a, b)``, phase
``atan2(b, a)``; smooth through zero, unlike amplitude and phase), the same
for ``friction.<side>.ripple[k]``; ``friction.<side>.breakaway_excess`` is
``breakaway - coulomb`` (so the two can be fitted together without ever
violating ``breakaway >= coulomb``).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from hdgym.effects import EFFECTS
from hdgym.params import GROUNDED, JointParams, from_dict, to_dict

_TOKEN = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)\])?$")


# --------------------------------------------------------------------- paths


def _tokens(path: str) -> list[tuple[str, int | None]]:
    out = []
    for part in path.split("."):
        m = _TOKEN.match(part)
        if not m:
            raise ValueError(f"unknown parameter {path!r}")
        out.append((m.group(1), None if m.group(2) is None else int(m.group(2))))
    return out


def _walk(d: Any, toks: list[tuple[str, int | None]], path: str) -> Any:
    for name, idx in toks:
        if not isinstance(d, Mapping) or name not in d:
            raise ValueError(f"unknown parameter {path!r}")
        d = d[name]
        if idx is not None:
            if not isinstance(d, list) or idx >= len(d):
                raise ValueError(f"unknown parameter {path!r} (no item {idx})")
            d = d[idx]
    return d


def _get_dict(d: Mapping[str, Any], path: str) -> float:
    toks = _tokens(path)
    last, _ = toks[-1]
    if last in ("sin", "cos"):
        item = _walk(d, toks[:-1], path)
        a, ph = item["amplitude"], item["phase"]
        return a * math.cos(ph) if last == "sin" else a * math.sin(ph)
    if last == "breakaway_excess":
        side = _walk(d, toks[:-1], path)
        return side["breakaway"] - side["coulomb"]
    v = _walk(d, toks, path)
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"parameter {path!r} is not a number")
    return float(v)


def _set_dict(d: dict[str, Any], path: str, value: float) -> None:
    toks = _tokens(path)
    last, idx = toks[-1]
    if last in ("sin", "cos"):
        item = _walk(d, toks[:-1], path)
        a = item["amplitude"] * math.cos(item["phase"])
        b = item["amplitude"] * math.sin(item["phase"])
        a, b = (value, b) if last == "sin" else (a, value)
        item["amplitude"] = math.hypot(a, b)
        item["phase"] = math.atan2(b, a)
        return
    if last == "breakaway_excess":
        side = _walk(d, toks[:-1], path)
        side["_excess"] = max(float(value), 0.0)
        return
    parent = _walk(d, toks[:-1], path)
    if not isinstance(parent, Mapping) or last not in parent:
        raise ValueError(f"unknown parameter {path!r}")
    if idx is None:
        parent[last] = float(value) if not isinstance(parent[last], int) else value
    else:
        parent[last][idx] = float(value)


def _fix_sides(d: dict[str, Any]) -> None:
    """Keep friction sides valid: breakaway >= coulomb, ripples sum to <= coulomb."""
    for side_name in ("input", "output"):
        side = d["friction"][side_name]
        side["coulomb"] = max(side["coulomb"], 0.0)
        if "_excess" in side:
            side["breakaway"] = side["coulomb"] + side.pop("_excess")
        side["breakaway"] = max(side["breakaway"], side["coulomb"])
        total = sum(r["amplitude"] for r in side["ripple"])
        if total > side["coulomb"] and total > 0:
            scale = side["coulomb"] / total * (1 - 1e-9)
            for r in side["ripple"]:
                r["amplitude"] *= scale


def get_value(p: JointParams, path: str) -> float:
    """Value at a dotted ``path`` (list items ``[k]`` and the virtual fields allowed)."""
    return _get_dict(to_dict(p), path)


def set_values(p: JointParams, values: Mapping[str, float]) -> JointParams:
    """A validated copy of ``p`` with every ``path -> value`` of ``values`` set."""
    d = to_dict(p)
    for path, v in values.items():
        _set_dict(d, path, v)
    _fix_sides(d)
    return from_dict(d, "params")


# -------------------------------------------------------------------- scales


@dataclass(frozen=True)
class Scales:
    """Data-derived sizes used for bounds and initial guesses (all output-referred).

    Attributes:
        torque: typical transmitted torque, N m (motor torque constant x ratio
            x command range).
        speed: typical output speed, rad/s.
        torsion: typical torsion, output rad.
        current: largest commanded current, A.
        current_measured: largest measured current, A (0 when not measured).
        voltage: largest voltage the amplifier was asked for, V.
        locked: locked-output record.
        inverse: torque-domain (inverse-dynamics) comparison; the compliance,
            hysteresis, kinematic-error and amplifier effects are not testable.
        transmission_error: typical size of output - motor/ratio, output rad.
        ke: ``(order, port, a, b)`` guesses of kinematic-error lines
            ``a sin + b cos`` (output rad; ``order`` relative to ``port``, as in
            :class:`hdgym.params.Harmonic`), regressed from the measured
            transmission error at the lines :func:`ke_lines` says the record resolves.
        ripple: ``(order, a, b)`` guesses of output-side friction ripple (N m),
            regressed from the measured acceleration while moving.
        static: ``(side, static, running)`` friction levels read from the record's
            pauses and runs (:func:`.residuals.friction_levels`; side ``output``,
            ``input`` or ``lumped``, N m in the side's frame): the largest torque
            held while stuck and the sign-of-velocity level while moving.
    """

    torque: float
    speed: float
    torsion: float
    current: float
    current_measured: float = 0.0
    voltage: float = 0.0
    locked: bool = False
    inverse: bool = False
    transmission_error: float = 0.0
    ke: tuple[tuple[float, str, float, float], ...] = ()
    ripple: tuple[tuple[float, float, float], ...] = ()
    static: tuple[tuple[str, float, float], ...] = ()


@dataclass(frozen=True)
class FitParam:
    """One fitted parameter: dotted ``path``, bounds and an initial guess (None: keep)."""

    path: str
    lower: float
    upper: float
    guess: float | None = None


@dataclass(frozen=True)
class Effect:
    """One effect of the vocabulary, as the workflow sees it.

    Attributes:
        name: the vocabulary word.
        signature: key of its signature function in ``residuals.SIGNATURES``.
        description: one line for reports.
        requires: effects that must be on for this one to act.
        testable: ``testable(scales)`` -> whether the record can show it at all.
        sized: ``sized(scales)`` -> whether :meth:`switch_on` reads its size
            parameters (those with lower bound 0) from the record; the trial start
            then searches near them instead of over their whole range.
    """

    name: str
    signature: str
    description: str
    _params: Callable[[JointParams, Scales], list[FitParam]] = field(repr=False)
    _on: Callable[[JointParams, Scales], dict[str, Any]] = field(repr=False)
    _neutral: Callable[[dict[str, Any]], None] = field(repr=False)
    requires: tuple[str, ...] = ()
    testable: Callable[[Scales], bool] = field(default=lambda s: True, repr=False)
    sized: Callable[[Scales], bool] = field(default=lambda s: False, repr=False)

    def fit_params(self, p: JointParams, s: Scales) -> list[FitParam]:
        """Parameters to fit for this effect, with bounds (containing the current value)."""
        out = []
        for fp in self._params(p, s):
            try:
                v = get_value(p, fp.path)
            except ValueError:
                v = fp.guess if fp.guess is not None else fp.lower
            lo, hi = min(fp.lower, v), max(fp.upper, v)
            out.append(FitParam(fp.path, lo, hi, fp.guess))
        return out

    def switch_on(self, p: JointParams, s: Scales) -> JointParams:
        """``p`` with this effect (and what it requires) on, at data-scaled initial guesses."""
        d = to_dict(p)
        for path, value in self._on(p, s).items():
            if path.startswith("@"):  # structural replacement of a whole table or list
                _assign(d, path[1:], value)
            else:
                _set_dict(d, path, value)
        _fix_sides(d)
        q = from_dict(d, "params")
        return q.with_effects(self.name, *self.requires)

    def neutral(self, p: JointParams) -> JointParams:
        """``p`` with this effect's parameters set so that it does nothing (switch unchanged)."""
        d = to_dict(p)
        self._neutral(d)
        _fix_sides(d)
        return from_dict(d, "params")


def _assign(d: dict[str, Any], path: str, value: Any) -> None:
    toks = _tokens(path)
    parent = _walk(d, toks[:-1], path)
    parent[toks[-1][0]] = value


# ------------------------------------------------------------------- effects

KE_ORDERS = (1.0, 2.0, 4.0)
"""Orders of the kinematic-error lines, per WG revolution relative to the spline whose tooth
errors make them (PHYSICS.md 2.1: 2 dominant, then 4, sometimes 1)."""
KE_SPLIT = 0.5
"""Least phase, rad, by which the other spline's line must drift against the grounded one's
over a record for the two to be fitted apart (:func:`ke_lines`)."""
RIPPLE_ORDERS = (1.0, 2.0)
N_SLIP = 3


def _sides(s: Scales) -> tuple[str, ...]:
    """Friction sides a record can inform: the motor side only when the output is locked,
    the output side only in the rigid (inverse) comparison, where both are one lumped
    friction."""
    if s.locked:
        return ("input",)
    return ("output",) if s.inverse else ("output", "input")


def _one_side(s: Scales) -> tuple[str, ...]:
    """Sides whose static friction is fitted: the motor side when the output is locked, the
    lumped output side in the rigid (inverse) comparison, else both (the motor breaks away
    before it winds up the spring enough to break the output loose)."""
    return _sides(s)


def _t_side(p: JointParams, s: Scales, side: str) -> float:
    """Torque scale on a friction side (motor-referred on the input side)."""
    return s.torque if side == "output" else s.torque / p.ratio


def _w_side(p: JointParams, s: Scales, side: str) -> float:
    return s.speed if side == "output" else s.speed * p.ratio


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


def _harmonic_guess(guess, order: float) -> tuple[float, float]:
    for o, a, b in guess:
        if o == order:
            return math.hypot(a, b), math.atan2(b, a)
    return 0.0, 0.0


def _ke_on(p, s):
    lines = s.ke or tuple((o, p.transmission.grounded, 0.0, 0.0) for o in KE_ORDERS)
    out = [{"order": o, "amplitude": math.hypot(a, b), "phase": math.atan2(b, a), "port": port}
           for o, port, a, b in lines]
    return {"@kinematic_error.harmonics": out}


def _ke_neutral(d):
    d["kinematic_error"]["harmonics"] = []


def _ripple_side(s: Scales) -> str:
    return "input" if s.locked else "output"


def _posdep_params(p, s):
    out = []
    for side in ("input", "output"):
        fs = getattr(p.friction, side)
        a = 0.7 * max(fs.coulomb, 1e-9)
        for k in range(len(fs.ripple)):
            out += [FitParam(f"friction.{side}.ripple[{k}].{c}", -a, a) for c in ("sin", "cos")]
    return out


def _posdep_on(p, s):
    side = _ripple_side(s)
    rip = []
    for o in RIPPLE_ORDERS:
        amp, ph = _harmonic_guess(s.ripple, o) if side == "output" else (0.0, 0.0)
        rip.append({"order": o, "amplitude": amp, "frame": "input", "phase": ph})
    d: dict[str, Any] = {f"@friction.{side}.ripple": rip}
    fs = getattr(p.friction, side)
    if fs.coulomb <= 0:
        d[f"friction.{side}.coulomb"] = 0.1 * _t_side(p, s, side)
    return d


def _posdep_neutral(d):
    for side in ("input", "output"):
        d["friction"][side]["ripple"] = []


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


def _nl_neutral(d):
    c = d["compliance"]
    c["cubic"] = 0.0
    c["extra_stiffness"] = 0.0
    if c["model"] == "three_segment":
        c["model"] = "linear"
    if c["model"] in ("cubic", "two_segment"):
        c["model"] = "cubic"


def _coul_params(p, s):
    return [FitParam(f"friction.{side}.coulomb", 0.0, _t_side(p, s, side))
            for side in _sides(s)]


def _coul_on(p, s):
    out = {}
    for side in _sides(s):
        f = 0.005 if (side == "input" and not s.locked) else 0.02
        out[f"friction.{side}.coulomb"] = f * _t_side(p, s, side)
    return out


def _coul_neutral(d):
    for side in ("input", "output"):
        d["friction"][side]["coulomb"] = 0.0
        d["friction"][side]["ripple"] = []


def _visc_params(p, s):
    return [FitParam(f"friction.{side}.viscous", 0.0,
                     2.0 * _t_side(p, s, side) / max(_w_side(p, s, side), 1e-9))
            for side in _sides(s)]


def _visc_on(p, s):
    out = {}
    for side in _sides(s):
        out[f"friction.{side}.viscous"] = (0.01 * _t_side(p, s, side)
                                           / max(_w_side(p, s, side), 1e-9))
        out[f"friction.{side}.cubic"] = 0.0
    return out


def _visc_neutral(d):
    for side in ("input", "output"):
        d["friction"][side]["viscous"] = 0.0
        d["friction"][side]["cubic"] = 0.0


def _strib_params(p, s):
    out = []
    for side in _one_side(s):
        w = _w_side(p, s, side)
        out += [FitParam(f"friction.{side}.breakaway_excess", 0.0, _t_side(p, s, side)),
                FitParam(f"friction.{side}.stribeck_velocity", 1e-3 * w, 2.0 * w)]
    return out


def _strib_on(p, s):
    out = _static_on(p, s, 0.02, running=False)
    for side in _one_side(s):
        out[f"friction.{side}.stribeck_velocity"] = 0.05 * _w_side(p, s, side)
    return out


def _levels(p: JointParams, s: Scales, side: str) -> tuple[float, float] | None:
    """``(static, running)`` levels of one friction side from the record, or None.

    A ``lumped`` reading (no torque sensor) goes to the output side, less what the
    model's motor side holds through the gear.
    """
    got = {name: (st, run) for name, st, run in s.static}
    if side in got:
        return got[side]
    if side == "output" and "lumped" in got:
        fi = p.friction.input
        st, run = got["lumped"]
        return max(st - fi.breakaway * p.ratio, 0.0), max(run - fi.coulomb * p.ratio, 0.0)
    return None


def _static_on(p, s, default: float, running: bool = True) -> dict[str, float]:
    """A static (breakaway) level switched on: from the record's levels where it has them.

    The largest torque held while stuck sets the breakaway level. For stiction
    (``running``) the running level sets ``coulomb`` too: the base fit had to
    stretch its Coulomb level towards the breakaway, and with a static level
    present the record's running level is the better start. (Stribeck friction
    keeps the fitted level: its friction falls with speed, so the level averaged
    over the runs is not its Coulomb level.) Sides the record cannot show start at
    ``default`` x the side's torque scale.
    """
    out = {}
    for side in _one_side(s):
        lv = _levels(p, s, side)
        if lv is None or lv[1] <= 0:
            out[f"friction.{side}.breakaway_excess"] = default * _t_side(p, s, side)
            continue
        static, run = lv
        coulomb = run if running else getattr(p.friction, side).coulomb
        if running:
            out[f"friction.{side}.coulomb"] = coulomb
        out[f"friction.{side}.breakaway_excess"] = max(static - coulomb, 0.0)
    return out


def _static_sized(s: Scales) -> bool:
    return bool(s.static)


def _stick_params(p, s):
    return [FitParam(f"friction.{side}.breakaway_excess", 0.0, _t_side(p, s, side))
            for side in _one_side(s)]


def _stick_on(p, s):
    return _static_on(p, s, 0.02)


def _break_neutral(d):
    for side in ("input", "output"):
        d["friction"][side]["breakaway"] = d["friction"][side]["coulomb"]


def _load_params(p, s):
    return [FitParam("friction.tooth_mu", 0.0, 1.0)]


def _load_on(p, s):
    return {"friction.tooth_mu": 0.02}


def _load_neutral(d):
    d["friction"]["tooth_mu"] = 0.0


def _amp_params(p, s):
    v = max(s.voltage, 1e-3)
    return [FitParam("amplifier.current_limit", 0.2 * s.current, 1.5 * s.current),
            FitParam("amplifier.voltage_limit", 0.2 * v, 3.0 * v)]


def _amp_on(p, s):
    cur = s.current_measured if s.current_measured > 0 else s.current
    return {"amplifier.current_limit": max(cur, 1e-6), "amplifier.voltage_limit": max(s.voltage,
                                                                                    1e-3)}


def _amp_neutral(d):
    d["amplifier"]["current_limit"] = 1e6
    d["amplifier"]["voltage_limit"] = 1e9


def _free(s: Scales) -> bool:
    return not s.locked


def _sim_only(s: Scales) -> bool:
    return not s.inverse


def _free_sim(s: Scales) -> bool:
    return not s.locked and not s.inverse


REGISTRY: dict[str, Effect] = {e.name: e for e in (
    Effect("kinematic_error", "order_lines_te",
           "kinematic error: output lags/leads motor/ratio periodically in the WG angle",
           _ke_params, _ke_on, _ke_neutral, testable=_free_sim),
    Effect("nonlinear_stiffness", "cubic_torsion",
           "hardening flexspline spring: residual cubic in the torsion",
           _nl_params, _nl_on, _nl_neutral, testable=_sim_only),
    Effect("hysteresis", "torsion_loops",
           "hysteresis in the torsion: residual loops against torsion (Maxwell slip)",
           _hyst_params, _hyst_on, _hyst_neutral, testable=_sim_only),
    Effect("coulomb_friction", "sign_steps",
           "Coulomb friction: residual steps with the sign of the velocity",
           _coul_params, _coul_on, _coul_neutral),
    Effect("viscous_friction", "speed_bins",
           "viscous friction: residual grows with speed",
           _visc_params, _visc_on, _visc_neutral),
    Effect("stribeck_friction", "speed_bins_low",
           "Stribeck friction: extra friction that decays with speed",
           _strib_params, _strib_on, _break_neutral, requires=("coulomb_friction",),
           sized=_static_sized),
    Effect("stiction", "breakaway",
           "stiction: breakaway torque above the running friction",
           _stick_params, _stick_on, _break_neutral, requires=("coulomb_friction",),
           testable=_sim_only, sized=_static_sized),
    Effect("position_dependent_friction", "order_lines_speed",
           "position-dependent friction: friction ripple at orders of the WG angle",
           _posdep_params, _posdep_on, _posdep_neutral, requires=("coulomb_friction",),
           testable=_free),
    Effect("load_dependent_friction", "torque_dependence",
           "load-dependent tooth friction: friction grows with the transmitted torque",
           _load_params, _load_on, _load_neutral, requires=("coulomb_friction",),
           testable=_free),
    Effect("amplifier_saturation", "clipped_current",
           "amplifier saturation: current clipped at the limit and by back-EMF at speed",
           _amp_params, _amp_on, _amp_neutral, testable=_sim_only),
)}

assert tuple(REGISTRY) == EFFECTS or set(REGISTRY) == set(EFFECTS)

CORE_PARAMS: tuple[tuple[str, float, float], ...] = (
    ("motor.inertia", 0.5, 2.0),
    ("load.inertia", 0.5, 2.0),
    ("compliance.stiffness", 0.5, 2.0),
)
"""Parameters every fit adjusts (path, lower and upper factor of the given value)."""


def core_params(p: JointParams, s: Scales) -> list[FitParam]:
    """The always-fitted parameters that the record can inform."""
    out = []
    for path, lo, hi in CORE_PARAMS:
        if s.locked and path == "load.inertia":
            continue
        if s.inverse and path == "compliance.stiffness":
            continue
        v = get_value(p, path)
        out.append(FitParam(path, lo * v, hi * v))
    return out


ANCHOR_FACTOR = 2.0
"""Parameters of the given base model are refined within this factor of their given value."""


def model_params(p: JointParams, s: Scales, anchor: JointParams | None = None
                 ) -> list[FitParam]:
    """Core parameters plus the fit parameters of every effect that is on (no duplicates).

    With ``anchor`` (the base model as given), the core parameters and those of the
    effects the anchor already has stay within :data:`ANCHOR_FACTOR` of their given
    (positive) values, so a base fit cannot wander off to mimic a missing effect;
    the parameters of effects added later keep the registry's data-scaled bounds.
    """
    out = core_params(p if anchor is None else anchor, s)
    seen = {fp.path for fp in out}
    for name in p.effects:
        eff = REGISTRY[name]
        if not eff.testable(s):
            continue
        anchored = anchor is not None and name in anchor.effects
        for fp in eff.fit_params(p, s):
            if fp.path in seen:
                continue
            seen.add(fp.path)
            if anchored and not fp.path.endswith((".sin", ".cos")):
                try:
                    v0 = get_value(anchor, fp.path)
                except ValueError:
                    v0 = 0.0
                if v0 > 0:
                    lo, hi = v0 / ANCHOR_FACTOR, v0 * ANCHOR_FACTOR
                    v = get_value(p, fp.path)
                    fp = FitParam(fp.path, min(lo, v), max(hi, v), fp.guess)
            out.append(fp)
    return out
