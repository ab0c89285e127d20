"""A sweep's unit of work: :class:`Job` (plain data, hashed into its id) and how
a job's randomized drive is drawn from its preset, grid point and spreads
(:func:`draw_params`).

A job's id also hashes the physics it runs on (:func:`physics_fingerprint`:
the simulator's physics and sensor sources and the resolved parameters of
its preset), and for scenarios that declare one, a digest of their task code
and config (:attr:`Job.task`), so a row computed before a physics, preset or
task change is not taken as done by a resumed sweep."""

from __future__ import annotations

import functools
import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass, field, is_dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from hdgym import params as P

__all__ = ["LEVEL_FIELDS", "PHYSICS_SOURCES", "Job", "as_param", "draw_params",
           "physics_fingerprint", "scale_level", "stable_hash"]

_HDGYM = Path(__file__).resolve().parent.parent
#: the sources that decide a simulated trajectory, relative to the hdgym package:
#: the physics step (every implementation) and the sensors and action scaling
PHYSICS_SOURCES = ("physics", "hardware.py")

# A spread on a part (not a leaf) scales that part's *level* with one common
# factor, keeping its internal constraints (breakaway >= coulomb, ripple <=
# coulomb, cubic <= 0). Which fields make the level of each part:
LEVEL_FIELDS: dict[type, tuple[str, ...]] = {
    P.FrictionSide: ("coulomb", "breakaway", "viscous", "cubic", "ripple"),
    P.Ripple: ("amplitude",),
    P.Friction: ("input", "output"),
    P.Hysteresis: ("element_stiffness", "element_strength", "width"),
    P.KinematicError: ("harmonics",),
    P.Harmonic: ("amplitude",),
}


def stable_hash(obj: Any, n: int = 16) -> str:
    """Hex digest of the canonical JSON of ``obj`` (sorted keys, no spaces)."""
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()[:n]


@functools.lru_cache(maxsize=1)
def _sources_digest() -> str:
    h = hashlib.sha256()
    for name in PHYSICS_SOURCES:
        path = _HDGYM / name
        files = sorted(path.rglob("*.py")) if path.is_dir() else [path]
        for f in files:
            h.update(f.relative_to(_HDGYM).as_posix().encode() + b"\0")
            h.update(f.read_bytes() + b"\0")
    return h.hexdigest()


def physics_fingerprint(p: P.JointParams) -> str:
    """16 hex digits naming the physics a run of ``p`` sees.

    Hashes the sources in :data:`PHYSICS_SOURCES` and the resolved parameters
    of ``p`` (every number and the effects; not its name, description or
    source notes): a change to the physics code, the sensors or a preset's
    numbers changes it.
    """
    d = P.to_dict(p)
    d.pop("meta", None)
    d.pop("sources", None)
    return stable_hash({"sources": _sources_digest(), "params": d})


@functools.lru_cache(maxsize=64)
def _fingerprint_of(preset: str, params_toml: str | None) -> str:
    base = P.loads(params_toml, preset) if params_toml is not None else P.preset(preset)
    return physics_fingerprint(base)


def _seed_words(digest: str) -> list[int]:
    return [int(digest[i : i + 8], 16) for i in range(0, len(digest), 8)]


@dataclass(frozen=True)
class Job:
    """One independent run: a drive, a scenario, a controller or agent, a seed.

    Everything here is plain data (JSON-able), so a job travels to a process
    pool or a Ray cluster as is; ``params_toml`` carries a drive read from a
    file so remote workers need no access to it.
    """

    preset: str
    scenario: str
    seed: int
    grid: Mapping[str, Any] = field(default_factory=dict)
    spreads: Mapping[str, float] = field(default_factory=dict)
    options: Mapping[str, Any] = field(default_factory=dict)
    controller: Mapping[str, Any] | None = None
    agent: Mapping[str, Any] | None = None
    quick: bool = False
    params_toml: str | None = None
    #: what the result depends on beyond the physics (the scenario's task code and
    #: config, :attr:`hdgym.sweep.scenarios.Scenario.task_digest`); '' for nothing
    task: str = ""
    #: where a job may keep files (trained policies); not an input, not hashed
    workdir: str | None = field(default=None, compare=False)

    def inputs(self) -> dict[str, Any]:
        """What defines the job (hashed into :attr:`job_id`), its physics included."""
        out = {"preset": self.preset, "scenario": self.scenario, "seed": self.seed,
               "grid": dict(self.grid), "spreads": dict(self.spreads),
               "options": dict(self.options), "controller": self.controller,
               "agent": self.agent, "quick": self.quick, "physics": self.physics}
        if self.params_toml is not None:
            out["params_sha256"] = hashlib.sha256(self.params_toml.encode()).hexdigest()
        if self.task:  # only when set, so the ids of scenarios without one stay as they were
            out["task"] = self.task
        return out

    @property
    def physics(self) -> str:
        """:func:`physics_fingerprint` of the job's base drive (before grid and spreads)."""
        return _fingerprint_of(self.preset, self.params_toml)

    @property
    def job_id(self) -> str:
        return stable_hash(self.inputs())

    @property
    def label(self) -> str:
        """Controller or agent name ('' for open-loop scenarios)."""
        src = self.controller or self.agent or {}
        return str(src.get("name", ""))

    def drive_rng(self) -> np.random.Generator:
        """Generator of the randomized drive: seed + preset, grid point, spreads."""
        digest = stable_hash({"preset": self.preset, "grid": dict(self.grid),
                              "spreads": dict(self.spreads), "params": self.params_toml})
        return np.random.default_rng([self.seed, *_seed_words(digest)])

    def run_rng(self) -> np.random.Generator:
        """Generator of the run (commands, noise): seed + drive + scenario + options."""
        digest = stable_hash({"preset": self.preset, "grid": dict(self.grid),
                              "spreads": dict(self.spreads), "params": self.params_toml,
                              "scenario": self.scenario, "options": dict(self.options)})
        return np.random.default_rng([self.seed, 1, *_seed_words(digest)])

    def run_seed(self) -> int:
        """An integer seed for APIs that take one (Simulator.run, env.reset)."""
        return int(self.run_rng().integers(0, 2**31 - 1))

    def base_params(self) -> P.JointParams:
        if self.params_toml is not None:
            return P.loads(self.params_toml, self.preset)
        return P.preset(self.preset)


def scale_level(obj: Any, factor: float, path: str) -> Any:
    """Scale the level fields of a part (see :data:`LEVEL_FIELDS`) by ``factor``."""
    if isinstance(obj, tuple):
        return tuple(scale_level(v, factor, path) for v in obj)
    if isinstance(obj, bool):
        raise ValueError(f"parameter {path} is not numeric; it cannot be randomized")
    if isinstance(obj, (int, float)):
        return obj * factor
    names = LEVEL_FIELDS.get(type(obj))
    if names is None:
        kinds = ", ".join(sorted(t.__name__ for t in LEVEL_FIELDS))
        raise ValueError(f"parameter {path} is not numeric and has no level to scale; "
                         f"parts with a level: {kinds}")
    return replace(obj, **{n: scale_level(getattr(obj, n), factor, f"{path}.{n}") for n in names})


def draw_params(base: P.JointParams, grid: Mapping[str, Any], spreads: Mapping[str, float],
                rng: np.random.Generator) -> tuple[P.JointParams, dict[str, Any]]:
    """Apply a grid point, then one draw per spread path (in sorted path order).

    A numeric leaf is scaled as :meth:`JointParams.perturb` does (each element
    of a tuple its own draw); a part listed in :data:`LEVEL_FIELDS` is scaled
    as a whole by one factor ``1 + spread * U(-1, 1)``.

    Returns:
        The drive and, per grid/spread path, what was drawn: the leaf's value
        (a list for tuples) or, for a part, its common factor.
    """
    p = base
    drawn: dict[str, Any] = {}
    for path in sorted(grid):
        p = p.set(path, as_param(grid[path]))
        drawn[path] = grid[path]
    for path in sorted(spreads):
        value = p.get(path)
        if is_dataclass(value):
            factor = 1.0 + spreads[path] * rng.uniform(-1.0, 1.0)
            p = p.set(path, scale_level(value, factor, path))
            drawn[path] = factor
        else:
            p = p.perturb(rng, {path: spreads[path]})
            v = p.get(path)
            drawn[path] = list(v) if isinstance(v, tuple) else v
    return p, drawn


def as_param(v: Any) -> Any:
    return tuple(v) if isinstance(v, list) else v
