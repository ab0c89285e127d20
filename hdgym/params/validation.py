"""Limits and checks shared by the parameter dataclasses.

Each part's ``__post_init__`` validates its own fields with :func:`require`
and :func:`finite`, so a bad value fails where it is built, and the error
names the field (``motor.inertia must be > 0 kg m^2, got -1``).
"""

from __future__ import annotations

import math
from dataclasses import fields
from typing import Any

#: the ports that can be held fixed (the other one is the output)
GROUNDED = ("flexspline", "circular_spline")
COMPLIANCE_MODELS = ("linear", "cubic", "two_segment", "three_segment")
HYSTERESIS_MODELS = ("maxwell", "tanh")
#: where the output side's friction acts: between the output and ground, or in the
#: tooth mesh between flexspline and circular spline (reflected to the wave generator)
FRICTION_PLACEMENTS = ("output", "mesh", "splines")
MAX_HARMONICS = 8
MAX_RIPPLES = 6
MAX_SLIP_ELEMENTS = 8


def finite(obj: Any, prefix: str) -> None:
    """Every number in a dataclass must be a finite number; the error names the field."""
    for f in fields(obj):
        value = getattr(obj, f.name)
        values = value if isinstance(value, tuple) else (value,)
        numeric = str(f.type) in ("float", "int") or str(f.type).startswith("tuple[float")
        for v in values:
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                if numeric:  # e.g. resistance = "3.4" in a TOML file
                    raise ValueError(f"{prefix}.{f.name} must be a number, got {v!r}")
                continue
            if not math.isfinite(v):
                raise ValueError(f"{prefix}.{f.name} must be finite, got {v!r}")


def require(cond: bool, name: str, what: str, value: Any) -> None:
    """Raise ``ValueError`` naming ``name`` unless ``cond`` holds."""
    if not cond:
        raise ValueError(f"{name} must be {what}, got {value!r}")
