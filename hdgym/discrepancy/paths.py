"""Dotted parameter paths: read and write one number of a :class:`JointParams` by name.

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
from collections.abc import Callable, Iterable, Mapping
from functools import lru_cache
from typing import Any

from hdgym.params import JointParams, from_dict, to_dict

_TOKEN = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)\])?$")


@lru_cache(maxsize=4096)
def _tokens(path: str) -> tuple[tuple[str, int | None], ...]:
    # cached: a fit parses the same few dozen paths at every residual evaluation
    out = []
    for part in path.split("."):
        m = _TOKEN.match(part)
        if not m:
            raise ValueError(f"unknown parameter {path!r}")
        out.append((m.group(1), None if m.group(2) is None else int(m.group(2))))
    return tuple(out)


def _walk(d: Any, toks: tuple[tuple[str, int | None], ...], path: str) -> Any:
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


def set_in_dict(d: dict[str, Any], path: str, value: float) -> None:
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


def fix_sides(d: dict[str, Any]) -> None:
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
    return setter(p)(values)


def reset_to(p: JointParams, given: JointParams, paths: Iterable[str]) -> JointParams:
    """``p`` with the parameters at ``paths`` back at their values in ``given``; ``p`` itself
    when that joint does not validate (the caller can tell by identity)."""
    try:
        return set_values(p, {path: get_value(given, path) for path in paths})
    except ValueError:
        return p


def setter(p: JointParams) -> Callable[[Mapping[str, float]], JointParams]:
    """:func:`set_values` on ``p`` as a function of the values alone, for many calls on one
    ``p`` (a fit builds a joint at every residual evaluation): ``p``'s mapping is made
    once and copied for each call."""
    plain = to_dict(p)

    def put(values: Mapping[str, float]) -> JointParams:
        d = _copy(plain)
        for path, v in values.items():
            set_in_dict(d, path, v)
        fix_sides(d)
        return from_dict(d, "params")

    return put


def _copy(x: Any) -> Any:
    """A copy of a mapping of tables, lists and numbers (:func:`to_dict`'s shape) that
    shares only the immutable leaves."""
    if isinstance(x, dict):
        return {k: _copy(v) for k, v in x.items()}
    if isinstance(x, list):
        return [_copy(v) for v in x]
    return x


def assign(d: dict[str, Any], path: str, value: Any) -> None:
    toks = _tokens(path)
    parent = _walk(d, toks[:-1], path)
    parent[toks[-1][0]] = value
