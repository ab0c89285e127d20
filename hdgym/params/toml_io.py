"""Parameters as TOML: build from / flatten to mappings, read, write (atomically)."""

from __future__ import annotations

import os
import tomllib
from collections.abc import Mapping
from dataclasses import fields, is_dataclass
from pathlib import Path
from typing import Any

from hdgym.effects import EFFECTS
from hdgym.files import atomic_write_text
from hdgym.params.joint import JointParams
from hdgym.params.parts import PARTS, FrictionSide, Harmonic, Ripple


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


def save(p: JointParams, path: str | os.PathLike[str]) -> None:
    """Write ``p`` as TOML (atomically)."""
    atomic_write_text(path, dumps(p))

