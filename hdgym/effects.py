"""The effect vocabulary: the names that switch physics on and off.

Every part of hdgym (the simulator's switches, the Gymnasium keyword
arguments, the discrepancy workflow) names effects with exactly these words.
Each effect maps to one bit of the integer flag word the compiled physics
reads, so a batch of environments can run with different effects.
"""

from __future__ import annotations

from collections.abc import Iterable

EFFECTS: tuple[str, ...] = (
    "kinematic_error",
    "nonlinear_stiffness",
    "hysteresis",
    "coulomb_friction",
    "viscous_friction",
    "stribeck_friction",
    "stiction",
    "position_dependent_friction",
    "load_dependent_friction",
    "amplifier_saturation",
)

#: bit of each effect in the physics flag word
BIT: dict[str, int] = {name: 1 << k for k, name in enumerate(EFFECTS)}
#: bit for the locked-output mode (a run mode, not an effect)
LOCKED_OUTPUT_BIT = 1 << len(EFFECTS)

#: effects that take energy out of the joint (the energy check switches these off)
DISSIPATIVE: tuple[str, ...] = (
    "hysteresis",
    "coulomb_friction",
    "viscous_friction",
    "stribeck_friction",
    "stiction",
    "position_dependent_friction",
    "load_dependent_friction",
)


def check_effects(names: Iterable[str], field: str = "effects") -> tuple[str, ...]:
    """Return ``names`` as a tuple in vocabulary order; raise on unknown names.

    Raises:
        ValueError: naming the field and the unknown effect, with the vocabulary.
    """
    names = tuple(names)
    for name in names:
        if name not in BIT:
            raise ValueError(
                f"{field}: unknown effect {name!r}; known effects are {', '.join(EFFECTS)}"
            )
    return tuple(e for e in EFFECTS if e in names)


def flags_of(effects: Iterable[str], locked_output: bool = False) -> int:
    """Integer flag word for the compiled physics."""
    word = 0
    for name in check_effects(effects):
        word |= BIT[name]
    if locked_output:
        word |= LOCKED_OUTPUT_BIT
    return word
