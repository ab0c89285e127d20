"""Sweeps: presets × randomized drives × controllers or policies × seeds.

``hdgym sweep SPEC.toml --out DIR [--backend ray [--address ADDR]] [--workers N]``
expands a spec (:mod:`hdgym.sweep.spec`) into independent jobs, runs them
on a local process pool or on Ray (:mod:`hdgym.sweep.backends`), appends one
row per finished job to ``DIR/results.csv`` (:mod:`hdgym.sweep.store`), and
ends with a summary table and figure (:mod:`hdgym.sweep.summary`). Re-running
the same command resumes: jobs whose id is already in ``results.csv`` are
skipped. Scenarios are pluggable by name (:mod:`hdgym.sweep.scenarios`).

Ready-made specs live in ``hdgym/sweep/specs/`` (:func:`spec_path`).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from hdgym.sweep.job import Job
from hdgym.sweep.runner import SweepResult, run_sweep
from hdgym.sweep.spec import SweepSpec, load_spec

__all__ = ["Job", "SweepResult", "SweepSpec", "load_spec", "run_sweep", "spec_names",
           "spec_path"]


def spec_names() -> list[str]:
    """Names of the bundled specs."""
    files = resources.files("hdgym.sweep.specs")
    return sorted(f.name[:-5] for f in files.iterdir() if f.name.endswith(".toml"))


def spec_path(name: str) -> Path:
    """Path of a bundled spec (e.g. ``controllers``)."""
    if name not in spec_names():
        raise ValueError(f"unknown bundled spec {name!r}; known: {', '.join(spec_names())}")
    return Path(str(resources.files("hdgym.sweep.specs").joinpath(f"{name}.toml")))
