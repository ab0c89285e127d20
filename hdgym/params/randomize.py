"""Randomized joints: each chosen parameter scaled by ``1 + spread * U(-1, 1)``.

Domain randomization (envs, sweeps) and robustness checks draw joints
around a preset with :func:`perturb`; the only randomness is the caller's
seeded ``numpy.random.Generator``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, Protocol, Self, TypeVar


class Settable(Protocol):
    """What :func:`perturb` needs of a joint: dotted-path get and a validated set."""

    def get(self, path: str) -> Any: ...

    def set(self, path: str, value: Any) -> Self: ...


J = TypeVar("J", bound=Settable)


def perturb(p: J, rng: Any, spreads: Mapping[str, float]) -> J:
    """A copy of ``p`` with each numeric parameter scaled by ``1 + spread * U(-1, 1)``.

    Args:
        p: the joint (a :class:`~hdgym.params.JointParams`).
        rng: a seeded ``numpy.random.Generator``.
        spreads: relative spread per dotted parameter path (>= 0); a tuple
            parameter draws one factor per element.

    Raises:
        ValueError: naming the path, for a negative spread or a non-numeric parameter.
    """
    out = p
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
