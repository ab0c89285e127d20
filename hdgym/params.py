"""Parameters of a harmonic-drive joint, as frozen, validated dataclasses.

One dataclass per physical part. All values are SI: rad, rad/s, N m, A, V,
s, kg m^2. Torques and stiffnesses of the transmission (compliance,
hysteresis, output friction, kinematic error, load) are *output-referred*;
motor and input-friction values are *motor-referred* (WG side).

Presets are TOML files in ``hdgym/presets/``; every number in a preset has an
entry in its ``[sources]`` table (paper and section, or the observation it
was chosen to reproduce). :func:`load` / :func:`save` read and write them.
"""

from __future__ import annotations

import math
import os
import tempfile
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field, fields, is_dataclass, replace
from importlib import resources
from pathlib import Path
from typing import Any

from hdgym.effects import EFFECTS, check_effects

GROUNDED = ("flexspline", "circular_spline")
COMPLIANCE_MODELS = ("linear", "cubic", "two_segment", "three_segment")
HYSTERESIS_MODELS = ("maxwell", "tanh")
MAX_HARMONICS = 8
MAX_RIPPLES = 6
MAX_SLIP_ELEMENTS = 8


def _finite(obj: Any, prefix: str) -> None:
    """Every float in a dataclass must be finite; the error names the field."""
    for f in fields(obj):
        value = getattr(obj, f.name)
        values = value if isinstance(value, tuple) else (value,)
        for v in values:
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                continue
            if not math.isfinite(v):
                raise ValueError(f"{prefix}.{f.name} must be finite, got {v!r}")


def _require(cond: bool, name: str, what: str, value: Any) -> None:
    if not cond:
        raise ValueError(f"{name} must be {what}, got {value!r}")


@dataclass(frozen=True)
class Motor:
    """Motor and wave generator, motor-referred.

    Attributes:
        inertia: rotor + wave generator inertia, kg m^2 (> 0).
        torque_constant: K_t, N m/A (> 0).
        back_emf_constant: K_b, V s/rad (>= 0).
        resistance: winding resistance R, ohm (> 0).
    """

    inertia: float
    torque_constant: float
    back_emf_constant: float = 0.0
    resistance: float = 1.0

    def __post_init__(self) -> None:
        _finite(self, "motor")
        _require(self.inertia > 0, "motor.inertia", "> 0 kg m^2", self.inertia)
        _require(self.torque_constant > 0, "motor.torque_constant", "> 0 N m/A",
                 self.torque_constant)
        _require(self.back_emf_constant >= 0, "motor.back_emf_constant", ">= 0 V s/rad",
                 self.back_emf_constant)
        _require(self.resistance > 0, "motor.resistance", "> 0 ohm", self.resistance)


@dataclass(frozen=True)
class Transmission:
    """Gear geometry and which port is grounded.

    Attributes:
        n: catalogue ratio N (flexspline teeth / tooth difference), > 1.
        grounded: ``"flexspline"`` (output on the circular spline, ratio N+1,
            same direction) or ``"circular_spline"`` (output on the
            flexspline, ratio N, opposite direction; the sign is folded into
            ``output_angle`` so the ideal output is ``motor_angle/ratio``).
    """

    n: float
    grounded: str = "circular_spline"

    def __post_init__(self) -> None:
        _finite(self, "transmission")
        _require(self.n > 1, "transmission.n", "> 1 (a reduction)", self.n)
        _require(self.grounded in GROUNDED, "transmission.grounded", f"one of {GROUNDED}",
                 self.grounded)

    @property
    def ratio(self) -> float:
        """Motor (WG) angle per output angle."""
        return self.n + 1.0 if self.grounded == "flexspline" else self.n

    def port_factor(self, port: str) -> float:
        """WG turns relative to ``port`` per WG turn relative to ground.

        Tooth errors of a port are sampled by the WG lobes at its angle
        relative to that port, so the split kinematic-error lines of the two
        splines sit at different orders of the (grounded-frame) WG angle.
        """
        if port == self.grounded:
            return 1.0
        # output port turns with +1/ratio (FS grounded) or -1/ratio physically
        sign = 1.0 if self.grounded == "flexspline" else -1.0
        return 1.0 - sign / self.ratio


@dataclass(frozen=True)
class Compliance:
    """Flexspline torsional stiffness, output-referred.

    ``model`` picks the spring when ``nonlinear_stiffness`` is on; with it
    off the spring is linear with ``stiffness``.

    Attributes:
        model: ``linear``, ``cubic`` (T = k1 x + k3 x^3), ``two_segment``
            (slope k1 inside +-knee, k1 + extra_stiffness outside) or
            ``three_segment`` (catalogue K1 to T1, K2 to T2, K3 above).
        stiffness: k1 / K1, N m/rad (> 0).
        cubic: k3, N m/rad^3 (>= 0).
        knee: theta0 of the two-segment spring, rad.
        extra_stiffness: k0 of the two-segment spring, N m/rad.
        segment_torques: (T1, T2) of the three-segment spring, N m.
        segment_stiffness: (K2, K3) of the three-segment spring, N m/rad.
        damping: structural damping across the spring, N m s/rad (>= 0).
    """

    stiffness: float
    model: str = "cubic"
    cubic: float = 0.0
    knee: float = 0.0
    extra_stiffness: float = 0.0
    segment_torques: tuple[float, float] = (0.0, 0.0)
    segment_stiffness: tuple[float, float] = (0.0, 0.0)
    damping: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "segment_torques", tuple(float(v) for v in self.segment_torques))
        object.__setattr__(self, "segment_stiffness",
                           tuple(float(v) for v in self.segment_stiffness))
        _finite(self, "compliance")
        _require(self.model in COMPLIANCE_MODELS, "compliance.model",
                 f"one of {COMPLIANCE_MODELS}", self.model)
        _require(self.stiffness > 0, "compliance.stiffness", "> 0 N m/rad", self.stiffness)
        _require(self.cubic >= 0, "compliance.cubic", ">= 0 N m/rad^3", self.cubic)
        _require(self.knee >= 0, "compliance.knee", ">= 0 rad", self.knee)
        _require(self.extra_stiffness >= 0, "compliance.extra_stiffness", ">= 0 N m/rad",
                 self.extra_stiffness)
        _require(self.damping >= 0, "compliance.damping", ">= 0 N m s/rad", self.damping)
        _require(len(self.segment_torques) == 2, "compliance.segment_torques", "two values",
                 self.segment_torques)
        _require(len(self.segment_stiffness) == 2, "compliance.segment_stiffness", "two values",
                 self.segment_stiffness)
        if self.model == "three_segment":
            t1, t2 = self.segment_torques
            _require(0 < t1 < t2, "compliance.segment_torques", "0 < T1 < T2", self.segment_torques)
            _require(min(self.segment_stiffness) > 0, "compliance.segment_stiffness", "> 0",
                     self.segment_stiffness)


@dataclass(frozen=True)
class Hysteresis:
    """Hysteresis in the flexspline torsion, output-referred.

    Attributes:
        model: ``maxwell`` (n Maxwell-slip elements) or ``tanh`` (Seyfferth's
            element with last-reversal memory).
        element_stiffness: kappa_i of the Maxwell-slip elements, N m/rad (>= 0).
        element_strength: slip strength W_i, N m (>= 0).
        width: B_f of the tanh element, N m (>= 0).
        shape: gamma of the tanh element, 1/rad (>= 0).
    """

    model: str = "maxwell"
    element_stiffness: tuple[float, ...] = ()
    element_strength: tuple[float, ...] = ()
    width: float = 0.0
    shape: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "element_stiffness",
                           tuple(float(v) for v in self.element_stiffness))
        object.__setattr__(self, "element_strength", tuple(float(v) for v in self.element_strength))
        _finite(self, "hysteresis")
        _require(self.model in HYSTERESIS_MODELS, "hysteresis.model",
                 f"one of {HYSTERESIS_MODELS}", self.model)
        _require(len(self.element_stiffness) == len(self.element_strength),
                 "hysteresis.element_strength", "as long as element_stiffness",
                 self.element_strength)
        _require(len(self.element_stiffness) <= MAX_SLIP_ELEMENTS, "hysteresis.element_stiffness",
                 f"at most {MAX_SLIP_ELEMENTS} elements", self.element_stiffness)
        for k, v in enumerate(self.element_stiffness):
            _require(v >= 0, f"hysteresis.element_stiffness[{k}]", ">= 0 N m/rad", v)
        for k, v in enumerate(self.element_strength):
            _require(v >= 0, f"hysteresis.element_strength[{k}]", ">= 0 N m (W)", v)
        _require(self.width >= 0, "hysteresis.width", ">= 0 N m", self.width)
        _require(self.shape >= 0, "hysteresis.shape", ">= 0 1/rad", self.shape)


@dataclass(frozen=True)
class Ripple:
    """One position-dependent friction harmonic ``amplitude * sin(order * angle + phase)``.

    Attributes:
        order: cycles per revolution of ``frame`` (> 0).
        frame: ``input`` (WG revolution) or ``output`` (output revolution).
        amplitude: N m, referred to the side the ripple belongs to (>= 0).
        phase: rad.
    """

    order: float
    amplitude: float
    frame: str = "input"
    phase: float = 0.0

    def __post_init__(self) -> None:
        _finite(self, "ripple")
        _require(self.order > 0, "ripple.order", "> 0", self.order)
        _require(self.amplitude >= 0, "ripple.amplitude", ">= 0 N m", self.amplitude)
        _require(self.frame in ("input", "output"), "ripple.frame", "'input' or 'output'",
                 self.frame)


@dataclass(frozen=True)
class FrictionSide:
    """Friction on one side of the gear.

    Running friction at speed w (each term switched by its effect):
    ``[Fc + sum_k A_k sin(order_k angle + phase_k) + (Fs - Fc) exp(-(w/ws)^2)] sgn(w)
    + b1 w + b2 w^3`` with the cubic clamped beyond its peak so viscous
    friction never falls. While stuck it holds up to ``breakaway``.

    Attributes:
        coulomb: Fc, N m (>= 0).
        breakaway: Fs, static friction, N m (>= coulomb).
        stribeck_velocity: ws, rad/s (> 0 when breakaway > coulomb).
        viscous: b1, N m s/rad (>= 0).
        cubic: b2, N m s^3/rad^3 (<= 0, Tuttle eq 3.22; clamped).
        ripple: position-dependent harmonics; amplitudes sum to at most Fc.
    """

    coulomb: float = 0.0
    breakaway: float = 0.0
    stribeck_velocity: float = 1.0
    viscous: float = 0.0
    cubic: float = 0.0
    ripple: tuple[Ripple, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "ripple", tuple(
            r if isinstance(r, Ripple) else Ripple(**r) for r in self.ripple))
        _finite(self, "friction")
        _require(self.coulomb >= 0, "friction.coulomb", ">= 0 N m", self.coulomb)
        _require(self.breakaway >= self.coulomb, "friction.breakaway", ">= coulomb",
                 self.breakaway)
        _require(self.stribeck_velocity > 0, "friction.stribeck_velocity", "> 0 rad/s",
                 self.stribeck_velocity)
        _require(self.viscous >= 0, "friction.viscous", ">= 0 N m s/rad", self.viscous)
        _require(self.cubic <= 0 or self.viscous == 0 and self.cubic >= 0, "friction.cubic",
                 "<= 0 (a falling cubic, Tuttle eq 3.22) or >= 0 with viscous 0", self.cubic)
        _require(len(self.ripple) <= MAX_RIPPLES, "friction.ripple",
                 f"at most {MAX_RIPPLES} harmonics", len(self.ripple))
        total = sum(r.amplitude for r in self.ripple)
        _require(total <= self.coulomb + 1e-12, "friction.ripple",
                 "amplitudes summing to at most coulomb (friction never negative)", total)


@dataclass(frozen=True)
class Friction:
    """Friction of the joint.

    Attributes:
        input: wave-generator bearing and motor, motor-referred N m.
        output: tooth mesh between flexspline and circular spline (acts on
            the output speed, which is the FS-CS relative speed in both
            configurations), output-referred N m.
        tooth_mu: Coulomb coefficient at the gear teeth (Tuttle model 5).
        tooth_angle: gear-tooth pressure angle, rad (Tuttle: 30 deg).
    """

    input: FrictionSide = field(default_factory=FrictionSide)
    output: FrictionSide = field(default_factory=FrictionSide)
    tooth_mu: float = 0.0
    tooth_angle: float = math.radians(30.0)

    def __post_init__(self) -> None:
        for side in ("input", "output"):
            v = getattr(self, side)
            if isinstance(v, Mapping):
                object.__setattr__(self, side, FrictionSide(**v))
        _finite(self, "friction")
        _require(self.tooth_mu >= 0, "friction.tooth_mu", ">= 0", self.tooth_mu)
        _require(0 <= self.tooth_angle < math.pi / 2, "friction.tooth_angle", "in [0, pi/2) rad",
                 self.tooth_angle)

    @property
    def load_coefficient(self) -> float:
        """mu' = mu / cos(alpha): tooth friction torque per N m transmitted.

        The normal force on a tooth flank at pressure angle alpha carries the
        tangential load T/r as T/(r cos alpha); friction mu F_N acts on the
        same pitch radius.
        """
        return self.tooth_mu / math.cos(self.tooth_angle)


@dataclass(frozen=True)
class Harmonic:
    """One kinematic-error harmonic ``amplitude * sin(order * angle + phase)``.

    Attributes:
        order: cycles per WG revolution relative to ``port`` (> 0).
        amplitude: output rad (>= 0).
        phase: rad.
        port: whose tooth errors make the line: ``circular_spline`` or
            ``flexspline``; the grounded port's line sits at ``order`` of the
            WG angle, the other's at ``order * (1 -+ 1/ratio)``.
    """

    order: float
    amplitude: float
    phase: float = 0.0
    port: str = "circular_spline"

    def __post_init__(self) -> None:
        _finite(self, "kinematic_error")
        _require(self.order > 0, "kinematic_error.order", "> 0", self.order)
        _require(self.amplitude >= 0, "kinematic_error.amplitude", ">= 0 rad", self.amplitude)
        _require(self.port in GROUNDED, "kinematic_error.port", f"one of {GROUNDED}", self.port)


@dataclass(frozen=True)
class KinematicError:
    """Kinematic error as a harmonic series in WG angle (output rad)."""

    harmonics: tuple[Harmonic, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "harmonics", tuple(
            h if isinstance(h, Harmonic) else Harmonic(**h) for h in self.harmonics))
        _require(len(self.harmonics) <= MAX_HARMONICS, "kinematic_error.harmonics",
                 f"at most {MAX_HARMONICS}", len(self.harmonics))


@dataclass(frozen=True)
class Load:
    """What the output drives.

    Attributes:
        inertia: output-side inertia (output port + load), kg m^2 (> 0).
        torque: constant external torque opposing positive motion, N m.
        gravity: m g l of an arm, N m; adds ``gravity * sin(output_angle)``.
    """

    inertia: float
    torque: float = 0.0
    gravity: float = 0.0

    def __post_init__(self) -> None:
        _finite(self, "load")
        _require(self.inertia > 0, "load.inertia", "> 0 kg m^2", self.inertia)


@dataclass(frozen=True)
class Amplifier:
    """Current amplifier (Tuttle App. C).

    Attributes:
        current_limit: I_max, A (> 0); commands are clipped to +-I_max.
        voltage_limit: supply V, V (> 0); current in
            [(-V - K_b w)/R, (V - K_b w)/R].
        bandwidth: current-loop bandwidth, Hz (> 0; first order).
    """

    current_limit: float
    voltage_limit: float
    bandwidth: float = 1000.0

    def __post_init__(self) -> None:
        _finite(self, "amplifier")
        _require(self.current_limit > 0, "amplifier.current_limit", "> 0 A", self.current_limit)
        _require(self.voltage_limit > 0, "amplifier.voltage_limit", "> 0 V", self.voltage_limit)
        _require(self.bandwidth > 0, "amplifier.bandwidth", "> 0 Hz", self.bandwidth)


@dataclass(frozen=True)
class Sensors:
    """Encoders and torque sensor.

    Attributes:
        motor_counts: input encoder counts per WG revolution after decoding (>= 1).
        output_counts: output encoder counts per output revolution (>= 1).
        torque_sensor: whether a flexspline torque sensor is fitted.
        torque_noise: torque-sensor noise standard deviation, N m (>= 0).
        current_noise: current-measurement noise standard deviation, A (>= 0).
        delay: samples of measurement delay, 0 or 1.
    """

    motor_counts: int = 4096
    output_counts: int = 80000
    torque_sensor: bool = True
    torque_noise: float = 0.0
    current_noise: float = 0.0
    delay: int = 0

    def __post_init__(self) -> None:
        _finite(self, "sensors")
        _require(int(self.motor_counts) == self.motor_counts and self.motor_counts >= 1,
                 "sensors.motor_counts", "a whole number >= 1", self.motor_counts)
        _require(int(self.output_counts) == self.output_counts and self.output_counts >= 1,
                 "sensors.output_counts", "a whole number >= 1", self.output_counts)
        _require(self.torque_noise >= 0, "sensors.torque_noise", ">= 0 N m", self.torque_noise)
        _require(self.current_noise >= 0, "sensors.current_noise", ">= 0 A", self.current_noise)
        _require(self.delay in (0, 1), "sensors.delay", "0 or 1 samples", self.delay)


@dataclass(frozen=True)
class Integration:
    """Fixed-step integration.

    Attributes:
        ctrl_dt: control (sample) period, s (> 0).
        n_substeps: physics substeps per control period (>= 1).
    """

    ctrl_dt: float = 1e-3
    n_substeps: int = 10

    def __post_init__(self) -> None:
        _finite(self, "integration")
        _require(self.ctrl_dt > 0, "integration.ctrl_dt", "> 0 s", self.ctrl_dt)
        _require(int(self.n_substeps) == self.n_substeps and self.n_substeps >= 1,
                 "integration.n_substeps", "a whole number >= 1", self.n_substeps)

    @property
    def dt(self) -> float:
        """Substep, s."""
        return self.ctrl_dt / self.n_substeps


PARTS: dict[str, type] = {
    "motor": Motor,
    "transmission": Transmission,
    "compliance": Compliance,
    "hysteresis": Hysteresis,
    "friction": Friction,
    "kinematic_error": KinematicError,
    "load": Load,
    "amplifier": Amplifier,
    "sensors": Sensors,
    "integration": Integration,
}


@dataclass(frozen=True)
class JointParams:
    """A whole joint: one instance of each part plus which effects are on."""

    motor: Motor
    transmission: Transmission
    compliance: Compliance
    load: Load
    amplifier: Amplifier
    hysteresis: Hysteresis = field(default_factory=Hysteresis)
    friction: Friction = field(default_factory=Friction)
    kinematic_error: KinematicError = field(default_factory=KinematicError)
    sensors: Sensors = field(default_factory=Sensors)
    integration: Integration = field(default_factory=Integration)
    effects: tuple[str, ...] = EFFECTS
    name: str = "custom"
    description: str = ""
    sources: Mapping[str, str] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        for key, cls in PARTS.items():
            if not isinstance(getattr(self, key), cls):
                raise ValueError(f"{key} must be a {cls.__name__}, got {type(getattr(self, key))}")
        object.__setattr__(self, "effects", check_effects(self.effects))

    @property
    def ratio(self) -> float:
        return self.transmission.ratio

    def without(self, *effects: str) -> JointParams:
        """The same joint with ``effects`` switched off."""
        check_effects(effects, "without")
        return replace(self, effects=tuple(e for e in self.effects if e not in effects))

    def with_effects(self, *effects: str) -> JointParams:
        """The same joint with ``effects`` switched on as well."""
        return replace(self, effects=check_effects(tuple(self.effects) + tuple(effects)))

    def get(self, path: str) -> Any:
        """Value at a dotted path such as ``compliance.stiffness`` or
        ``friction.input.ripple[0].amplitude`` (the paths of :func:`numeric_paths`)."""
        obj: Any = self
        for part in path.split("."):
            name, index = _split_index(part, path)
            if not is_dataclass(obj) or not hasattr(obj, name) or name == "sources":
                raise ValueError(f"unknown parameter {path!r}")
            obj = getattr(obj, name)
            if index is not None:
                obj = _item(obj, index, path)
        return obj

    def set(self, path: str, value: Any) -> JointParams:
        """A copy with the dotted ``path`` set to ``value`` (validated)."""
        return _set_in(self, path.split("."), value, path)

    def perturb(self, rng: Any, spreads: Mapping[str, float]) -> JointParams:
        """A copy with each numeric parameter scaled by ``1 + spread * U(-1, 1)``.

        Args:
            rng: a seeded ``numpy.random.Generator``.
            spreads: relative spread per dotted parameter path (>= 0).
        """
        out = self
        for path, spread in spreads.items():
            if not (spread >= 0 and math.isfinite(spread)):
                raise ValueError(f"spread of {path} must be >= 0, got {spread!r}")
            value = out.get(path)
            if isinstance(value, tuple):
                new = tuple(v * (1 + spread * rng.uniform(-1, 1)) for v in value)
            elif isinstance(value, (int, float)) and not isinstance(value, bool):
                new = value * (1 + spread * rng.uniform(-1, 1))
            else:
                raise ValueError(f"parameter {path} is not numeric; it cannot be randomized")
            out = out.set(path, new)
        return out


def _split_index(part: str, full: str) -> tuple[str, int | None]:
    """``"ripple[1]"`` -> ``("ripple", 1)``; ``"coulomb"`` -> ``("coulomb", None)``."""
    if not part.endswith("]"):
        return part, None
    name, _, index = part[:-1].partition("[")
    if not index.isdigit():
        raise ValueError(f"unknown parameter {full!r}")
    return name, int(index)


def _item(seq: Any, index: int, full: str) -> Any:
    if not isinstance(seq, tuple) or index >= len(seq):
        raise ValueError(f"unknown parameter {full!r}")
    return seq[index]


def _set_in(obj: Any, parts: list[str], value: Any, full: str) -> Any:
    name, index = _split_index(parts[0], full)
    if not is_dataclass(obj) or not hasattr(obj, name) or name == "sources":
        raise ValueError(f"unknown parameter {full!r}")
    current = getattr(obj, name)
    if index is None:
        new = _set_in(current, parts[1:], value, full) if parts[1:] else value
    else:
        item = _item(current, index, full)
        item = _set_in(item, parts[1:], value, full) if parts[1:] else value
        new = current[:index] + (item,) + current[index + 1:]
    return replace(obj, **{name: new})


# ---------------------------------------------------------------- TOML in/out


def _build(cls: type, data: Mapping[str, Any], where: str) -> Any:
    if not isinstance(data, Mapping):
        raise ValueError(f"{where}: expected a table, got {type(data).__name__}")
    names = {f.name for f in fields(cls)}
    unknown = set(data) - names
    if unknown:
        raise ValueError(f"{where}: unknown field(s) {', '.join(sorted(unknown))}")
    kwargs = {}
    for key, value in data.items():
        if isinstance(value, list):
            value = tuple(value)
        kwargs[key] = value
    try:
        return cls(**kwargs)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


def from_dict(data: Mapping[str, Any], where: str = "params") -> JointParams:
    """Build :class:`JointParams` from a TOML-shaped mapping."""
    data = dict(data)
    meta = data.pop("meta", {})
    sources = data.pop("sources", {})
    effects = data.pop("effects", {}).get("on", list(EFFECTS))
    unknown = set(data) - set(PARTS)
    if unknown:
        raise ValueError(f"{where}: unknown section(s) {', '.join(sorted(unknown))}")
    parts = {}
    for key, cls in PARTS.items():
        if key not in data:
            if key in ("motor", "transmission", "compliance", "load", "amplifier"):
                raise ValueError(f"{where}: missing section [{key}]")
            continue
        section = data[key]
        if key == "friction":
            section = dict(section)
            for side in ("input", "output"):
                if side in section:
                    s = dict(section[side])
                    s["ripple"] = tuple(_build(Ripple, r, f"{where} [[friction.{side}.ripple]]")
                                        for r in s.get("ripple", ()))
                    section[side] = _build(FrictionSide, s, f"{where} [friction.{side}]")
        if key == "kinematic_error":
            section = dict(section)
            section["harmonics"] = tuple(
                _build(Harmonic, h, f"{where} [[kinematic_error.harmonics]]")
                for h in section.get("harmonics", ()))
        parts[key] = _build(cls, section, f"{where} [{key}]")
    return JointParams(**parts, effects=tuple(effects), name=meta.get("name", "custom"),
                       description=meta.get("description", ""), sources=dict(sources))


def to_dict(p: JointParams) -> dict[str, Any]:
    """The TOML-shaped mapping of ``p`` (inverse of :func:`from_dict`)."""
    out: dict[str, Any] = {"meta": {"name": p.name, "description": p.description},
                           "effects": {"on": list(p.effects)}}
    for key in PARTS:
        out[key] = _plain(getattr(p, key))
    if p.sources:
        out["sources"] = dict(p.sources)
    return out


def _plain(obj: Any) -> Any:
    if is_dataclass(obj):
        return {f.name: _plain(getattr(obj, f.name)) for f in fields(obj)}
    if isinstance(obj, tuple):
        return [_plain(v) for v in obj]
    return obj


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def _toml_table(name: str, table: Mapping[str, Any], lines: list[str]) -> None:
    scalars = {k: v for k, v in table.items()
               if not isinstance(v, Mapping) and not (isinstance(v, list) and v
                                                       and isinstance(v[0], Mapping))}
    lines.append(f"[{name}]")
    for k, v in scalars.items():
        key = k if k.replace("_", "").isalnum() else _toml_value(k)
        lines.append(f"{key} = {_toml_value(v)}")
    lines.append("")
    for k, v in table.items():
        if isinstance(v, Mapping):
            _toml_table(f"{name}.{k}", v, lines)
        elif isinstance(v, list) and v and isinstance(v[0], Mapping):
            for item in v:
                lines.append(f"[[{name}.{k}]]")
                for kk, vv in item.items():
                    lines.append(f"{kk} = {_toml_value(vv)}")
                lines.append("")


def dumps(p: JointParams) -> str:
    """TOML text of ``p``."""
    lines: list[str] = []
    for name, table in to_dict(p).items():
        _toml_table(name, table, lines)
    return "\n".join(lines)


def loads(text: str, where: str = "params") -> JointParams:
    """Parse TOML text into :class:`JointParams`."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{where}: not valid TOML: {exc}") from None
    return from_dict(data, where)


def load(path: str | os.PathLike[str]) -> JointParams:
    """Read a parameter TOML file."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ValueError(f"{path}: cannot read: {exc.strerror}") from None
    return loads(text, str(path))


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file and a rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def save(p: JointParams, path: str | os.PathLike[str]) -> None:
    """Write ``p`` as TOML (atomically)."""
    atomic_write_text(path, dumps(p))


def preset_names() -> list[str]:
    """Names of the bundled presets."""
    files = resources.files("hdgym.presets")
    return sorted(f.name[:-5] for f in files.iterdir() if f.name.endswith(".toml"))


def preset(name: str) -> JointParams:
    """Load a bundled preset by name (e.g. ``tuttle-joint1``)."""
    names = preset_names()
    if name not in names:
        raise ValueError(f"preset: unknown preset {name!r}; known presets are {', '.join(names)}")
    text = resources.files("hdgym.presets").joinpath(f"{name}.toml").read_text()
    return loads(text, f"preset {name}")


def numeric_paths(p: JointParams) -> list[str]:
    """Dotted paths of every numeric field (for source checks and randomization)."""
    out: list[str] = []

    def walk(obj: Any, prefix: str) -> None:
        for f in fields(obj):
            v = getattr(obj, f.name)
            path = f"{prefix}.{f.name}"
            if is_dataclass(v):
                walk(v, path)
            elif isinstance(v, tuple) and v and is_dataclass(v[0]):
                for k, item in enumerate(v):
                    walk(item, f"{path}[{k}]")
            elif isinstance(v, (int, float, tuple)) and not isinstance(v, bool):
                out.append(path)

    for key in PARTS:
        walk(getattr(p, key), key)
    return out

