"""What the packages built on hdgym add to it, found through entry points.

hdgym never imports its users (``controllers``, ``agents`` or yours). A
package that adds sweep scenarios or bench sections names a module under an
entry-point group in its ``pyproject.toml``; importing that module registers
what it adds (with :func:`hdgym.sweep.scenarios.register` or
:func:`hdgym.bench.register_section`)::

    [project.entry-points."hdgym.sweep_scenarios"]
    mypkg = "mypkg.sweep"

    [project.entry-points."hdgym.bench_sections"]
    mypkg = "mypkg.bench"

The groups are read when a registry is asked for a name it does not hold,
so a process-pool worker or a Ray node (where the package is installed too)
finds the same scenarios as the process that started the sweep.
"""

from __future__ import annotations

from importlib import metadata

__all__ = ["BENCH_SECTIONS", "SWEEP_SCENARIOS", "load"]

#: entry-point group of modules that register ``hdgym sweep`` scenarios
SWEEP_SCENARIOS = "hdgym.sweep_scenarios"
#: entry-point group of modules that register ``hdgym bench`` sections
BENCH_SECTIONS = "hdgym.bench_sections"

_loaded: set[tuple[str, str, str]] = set()


def load(group: str) -> dict[str, str]:
    """Import every module named under the entry-point ``group`` not imported yet.

    Returns ``{entry point name: why it failed}`` for the ones that could not
    be imported this time (e.g. an optional extra is missing), so a caller
    can say why a name it was asked for is unknown; never raises for them.
    """
    failed: dict[str, str] = {}
    for ep in metadata.entry_points(group=group):
        key = (group, ep.name, ep.value)
        if key in _loaded:
            continue
        try:
            ep.load()
        except Exception as exc:  # noqa: BLE001 - a broken plugin must not break hdgym
            failed[ep.name] = f"cannot import {ep.value} ({type(exc).__name__}: {exc})"
            continue
        _loaded.add(key)
    return failed
