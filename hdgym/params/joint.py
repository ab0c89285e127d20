"""A whole joint (:class:`JointParams`): its parts, the effects that are on, dotted-path access."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields, is_dataclass, replace
from typing import Any

from hdgym.effects import EFFECTS, check_effects
from hdgym.params.parts import (
    PARTS,
    Amplifier,
    Compliance,
    Friction,
    Hysteresis,
    Integration,
    KinematicError,
    Load,
    Motor,
    Sensors,
    Transmission,
)


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
        from hdgym.params.randomize import perturb  # one job per module

        return perturb(self, rng, spreads)


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

