"""What every controller shares: the call protocol and argument checks."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Protocol, runtime_checkable

#: one sample of measurements: channel name -> value (SI: rad, rad/s, N m, A, s)
Measurement = Mapping[str, float]


@runtime_checkable
class Controller(Protocol):
    """Measurements in, current command out (A)."""

    def reset(self) -> None:
        """Start a new run (called by the closed-loop runner before the first sample)."""

    def __call__(self, t: float, measurement: Measurement) -> float:
        """Current command in A for time ``t`` (s)."""


def check_finite(name: str, value: float) -> float:
    """``float(value)``; raise ``ValueError`` naming ``name`` if it is not finite."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return v


def check_nonneg(name: str, value: float, unit: str = "") -> float:
    """A finite value >= 0 (gains that make no sense negative)."""
    v = check_finite(name, value)
    if v < 0:
        raise ValueError(f"{name} must be >= 0{' ' + unit if unit else ''}, got {value!r}")
    return v


def check_positive(name: str, value: float, unit: str = "") -> float:
    """A finite value > 0."""
    v = check_finite(name, value)
    if v <= 0:
        raise ValueError(f"{name} must be > 0{' ' + unit if unit else ''}, got {value!r}")
    return v


def check_orders(name: str, orders: object) -> tuple[float, ...]:
    """A non-empty sequence of positive, finite orders (cycles per revolution)."""
    try:
        values = tuple(float(o) for o in orders)  # type: ignore[union-attr]
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a sequence of positive numbers, got {orders!r}") from None
    for o in values:
        if not (math.isfinite(o) and o > 0):
            raise ValueError(f"{name} must contain only positive orders, got {o!r} in {orders!r}")
    if len(set(values)) != len(values):
        raise ValueError(f"{name} must not repeat an order, got {orders!r}")
    return values
