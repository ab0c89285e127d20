"""Sweep specs: a TOML file naming presets, spreads, grids, controllers, agents,
scenarios and seeds, expanded into independent :class:`Job` s.

A spec (every key but ``presets``, ``scenarios`` and ``seeds`` is optional)::

    [sweep]
    name = "open-loop"                  # names the summary files
    presets = ["tuttle-joint1", "my_drive.toml"]   # bundled names or files (relative to the spec)
    scenarios = ["current_steps", "locked_random"] # see hdgym.sweep.scenarios.scenario_names()
    seeds = 4                           # 0..3, or a list [0, 7, 11]
    quick = false                       # shorter runs in every scenario
    summary_dir = "runs/sweeps"         # also write <name>.md / <name>.png here

    [spreads]                           # relative, one uniform draw per path per job
    "compliance.stiffness" = 0.3        # stiffness * (1 + 0.3 U(-1, 1))
    "friction.output" = 0.3             # a friction side: one factor on its whole level

    [grid]                              # explicit values; the sweep takes the product
    "load.inertia" = [0.5, 1.0]

    [scenario.current_steps]            # options handed to one scenario
    currents = [0.5, 1.0, 2.0]

    [[controllers]]                     # for controllers:* scenarios; `name` labels the rows
    name = "pid"
    kind = "pid"

    [[agents]]                          # for rl_train; `name` labels the rows
    name = "ppo"
    config = "ppo_default"

Jobs are the product presets x grid points x scenarios x (controllers | agents
| one open-loop slot) x seeds. Each is independent; its id is a stable hash of
its inputs (:attr:`Job.job_id`), so a sweep resumes by skipping ids it has
already written.

Randomness: a job's randomized drive comes from ``default_rng([seed, hash of
preset + grid point + spreads])`` and its run noise from ``default_rng([seed,
hash of that + scenario + options])``. Neither depends on the controller or
agent, so every controller of a seed meets the same drive and the same noise
(common random numbers: paired comparisons).

Bad specs raise :class:`ValueError` before any job runs, naming the spec file
and the line of the offending key.
"""

from __future__ import annotations

import itertools
import math
import re
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, is_dataclass
from pathlib import Path
from typing import Any

from hdgym import params as P
from hdgym.sweep.job import Job, as_param, scale_level

__all__ = ["SweepSpec", "find_line", "load_spec", "parse_spec"]

SWEEP_KEYS = {"name", "description", "presets", "scenarios", "seeds", "quick", "summary_dir"}
TOP_KEYS = {"sweep", "spreads", "grid", "scenario", "controllers", "agents"}

# ------------------------------------------------------------- line numbers


_HEADER = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")


def _norm_key(k: str) -> str:
    return ".".join(part.strip().strip('"').strip("'").strip() for part in
                    re.findall(r'"[^"]*"|\'[^\']*\'|[^.]+', k))


def find_line(text: str, table: str | None, key: str | None = None, index: int = 0) -> int | None:
    """1-based line of ``key =`` inside ``[table]`` (or of the table header).

    ``table`` None means the top level (before any header); ``index`` picks
    the n-th ``[[table]]`` of an array of tables. Quoted keys are matched
    with or without their quotes.
    """
    lines = text.splitlines()
    start, seen = None, -1
    if table is None:
        start = 0
    else:
        for i, line in enumerate(lines):
            m = _HEADER.match(line)
            if m and _norm_key(m.group(2)) == table:
                seen += 1
                if seen == index:
                    start = i
                    break
        if start is None:
            return None
        if key is None:
            return start + 1
        start += 1
    for i in range(start, len(lines)):
        line = lines[i]
        if _HEADER.match(line):
            break
        m = re.match(r"^\s*(\"[^\"]*\"|'[^']*'|[A-Za-z0-9_.\-\s\"']+?)\s*=", line)
        if m and _norm_key(m.group(1)) == key:
            return i + 1
    return None


# ------------------------------------------------------------------ the spec


@dataclass
class SweepSpec:
    """A parsed, validated sweep spec."""

    path: Path
    text: str
    name: str
    presets: list[str]
    scenarios: list[str]
    seeds: list[int]
    spreads: dict[str, float]
    grid: dict[str, list[Any]]
    options: dict[str, dict[str, Any]]
    controllers: list[dict[str, Any]]
    agents: list[dict[str, Any]]
    quick: bool = False
    summary_dir: str | None = None
    description: str = ""
    preset_files: dict[str, str] = field(default_factory=dict)

    def grid_points(self) -> list[dict[str, Any]]:
        keys = sorted(self.grid)
        return [dict(zip(keys, combo, strict=True))
                for combo in itertools.product(*(self.grid[k] for k in keys))]

    def jobs(self) -> list[Job]:
        """Every job, in a fixed order (presets, grid, scenarios, controllers, seeds)."""
        from hdgym.sweep.scenarios import get_scenario

        out: list[Job] = []
        for preset in self.presets:
            for point in self.grid_points():
                for scen in self.scenarios:
                    sc = get_scenario(scen)
                    kind = sc.needs
                    slots: Sequence[dict[str, Any] | None]
                    if kind == "controller":
                        slots = self.controllers
                    elif kind == "agent":
                        slots = self.agents
                    else:
                        slots = [None]
                    for slot in slots:
                        task = sc.task_digest(slot) if sc.task_digest is not None else ""
                        for seed in self.seeds:
                            out.append(Job(
                                preset=preset, scenario=scen, seed=seed, grid=point,
                                spreads=dict(self.spreads), options=self.options.get(scen, {}),
                                controller=slot if kind == "controller" else None,
                                agent=slot if kind == "agent" else None,
                                quick=self.quick, params_toml=self.preset_files.get(preset),
                                task=task))
        return out


class _Where:
    """Builds ``spec.toml, line N: message`` errors."""

    def __init__(self, path: Path, text: str):
        self.path, self.text = path, text

    def error(self, msg: str, table: str | None = None, key: str | None = None,
              index: int = 0) -> ValueError:
        line = find_line(self.text, table, key, index)
        if line is None and key is not None and table is not None:
            # the key may sit in a sub-table: [spreads.compliance] stiffness = ...
            parts = key.split(".")
            for cut in range(1, len(parts)):
                sub = ".".join([table, *parts[:cut]])
                line = find_line(self.text, sub, ".".join(parts[cut:]), index)
                if line is not None:
                    break
        if line is None and key is not None:
            line = find_line(self.text, table, None, index)
        where = f"{self.path}, line {line}" if line else f"{self.path}"
        return ValueError(f"{where}: {msg}")


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def load_spec(path: str | Path, *, quick: bool | None = None) -> SweepSpec:
    """Read and validate a sweep spec; raise ValueError naming file and line.

    Args:
        path: the spec TOML.
        quick: override the spec's ``quick`` key.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise ValueError(f"{path}: cannot read: {exc.strerror}") from None
    return parse_spec(text, path, quick=quick)


def parse_spec(text: str, path: str | Path = "spec.toml", *, quick: bool | None = None
               ) -> SweepSpec:
    """Validate spec ``text`` (``path`` names it in errors and anchors preset files)."""
    from hdgym.sweep.scenarios import check_options, get_scenario, scenario_names

    path = Path(path)
    w = _Where(path, text)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML: {exc}") from None

    for key in data:
        if key not in TOP_KEYS:
            raise w.error(f"unknown key {key!r}; known: {', '.join(sorted(TOP_KEYS))}",
                          None if not isinstance(data[key], dict) else key,
                          key if not isinstance(data[key], dict) else None)
    sweep = data.get("sweep")
    if not isinstance(sweep, dict):
        raise w.error("missing [sweep] table (presets, scenarios, seeds)")
    for key in sweep:
        if key not in SWEEP_KEYS:
            raise w.error(f"unknown key {key!r} in [sweep]; known: "
                          f"{', '.join(sorted(SWEEP_KEYS))}", "sweep", key)
    for key in ("presets", "scenarios", "seeds"):
        if key not in sweep:
            raise w.error(f"[sweep] needs {key!r}", "sweep")

    name = sweep.get("name", path.stem)
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z0-9_.\-]+", name):
        raise w.error(f"name must be letters, digits, '_', '-', '.', got {name!r}", "sweep", "name")

    # presets: bundled names or TOML files relative to the spec
    presets = sweep["presets"]
    if not isinstance(presets, list) or not presets or not all(isinstance(p, str) for p in presets):
        raise w.error("presets must be a non-empty list of preset names or .toml files",
                      "sweep", "presets")
    if len(set(presets)) != len(presets):
        raise w.error("presets lists a preset twice", "sweep", "presets")
    known = P.preset_names()
    bases: dict[str, P.JointParams] = {}
    files: dict[str, str] = {}
    for name_ in presets:
        if name_.endswith(".toml"):
            f = (path.parent / name_) if not Path(name_).is_absolute() else Path(name_)
            try:
                ptext = f.read_text()
            except OSError as exc:
                raise w.error(f"preset file {name_!r}: cannot read: {exc.strerror}",
                              "sweep", "presets") from None
            try:
                bases[name_] = P.loads(ptext, str(f))
            except ValueError as exc:
                raise w.error(f"preset file {name_!r}: {exc}", "sweep", "presets") from None
            files[name_] = ptext
        else:
            if name_ not in known:
                raise w.error(f"unknown preset {name_!r}; known presets: "
                              f"{', '.join(known) or '(none bundled)'}", "sweep", "presets")
            bases[name_] = P.preset(name_)

    # seeds
    seeds = sweep["seeds"]
    if _is_number(seeds) and int(seeds) == seeds and seeds > 0:
        seeds = list(range(int(seeds)))
    if (not isinstance(seeds, list) or not seeds
            or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in seeds)):
        raise w.error("seeds must be a count > 0 or a non-empty list of integers >= 0",
                      "sweep", "seeds")
    if len(set(seeds)) != len(seeds):
        raise w.error("seeds lists a seed twice", "sweep", "seeds")

    q = sweep.get("quick", False)
    if not isinstance(q, bool):
        raise w.error(f"quick must be true or false, got {q!r}", "sweep", "quick")
    if quick is not None:
        q = quick
    summary_dir = sweep.get("summary_dir")
    if summary_dir is not None and not isinstance(summary_dir, str):
        raise w.error("summary_dir must be a path string", "sweep", "summary_dir")
    description = sweep.get("description", "")
    if not isinstance(description, str):
        raise w.error("description must be a string", "sweep", "description")

    # spreads
    spreads_t = data.get("spreads", {})
    if not isinstance(spreads_t, dict):
        raise w.error("spreads must be a table of dotted path = relative spread", None, "spreads")
    spreads = _flatten(spreads_t)
    for key, v in spreads.items():
        if not _is_number(v) or not math.isfinite(v) or v < 0:
            raise w.error(f"spread of {key!r} must be a number >= 0 (relative), got {v!r}",
                          "spreads", key)
        if v >= 1:
            raise w.error(f"spread of {key!r} must be < 1 (a relative spread of {v} can flip "
                          f"the sign)", "spreads", key)
        for pname, base in bases.items():
            try:
                value = base.get(key)
                if isinstance(value, str | bool) or value is None:
                    raise ValueError(f"parameter {key} is not numeric; it cannot be randomized")
                if is_dataclass(value):
                    scale_level(value, 1.0, key)
            except ValueError as exc:
                raise w.error(f"spreads: {exc} (preset {pname})", "spreads", key) from None
    spreads = {k: float(v) for k, v in spreads.items()}

    # grid
    grid_t = data.get("grid", {})
    if not isinstance(grid_t, dict):
        raise w.error("grid must be a table of dotted path = [values]", None, "grid")
    grid = _flatten(grid_t)
    for key, values in grid.items():
        if not isinstance(values, list):
            raise w.error(f"grid {key!r} must be a list of values, got {values!r}", "grid", key)
        if not values:
            raise w.error(f"grid {key!r} is empty; give at least one value", "grid", key)
        for pname, base in bases.items():
            try:
                base.get(key)
                for v in values:
                    base.set(key, as_param(v))
            except (ValueError, TypeError) as exc:
                raise w.error(f"grid: {exc} (preset {pname})", "grid", key) from None

    # scenarios
    scenarios = sweep["scenarios"]
    if (not isinstance(scenarios, list) or not scenarios
            or not all(isinstance(s, str) for s in scenarios)):
        raise w.error("scenarios must be a non-empty list of scenario names", "sweep", "scenarios")
    if len(set(scenarios)) != len(scenarios):
        raise w.error("scenarios lists a scenario twice", "sweep", "scenarios")
    for s in scenarios:
        try:
            get_scenario(s)
        except ValueError as exc:
            raise w.error(f"{exc}; known: {', '.join(scenario_names())}",
                          "sweep", "scenarios") from None

    # per-scenario options
    options_t = data.get("scenario", {})
    if not isinstance(options_t, dict):
        raise w.error("scenario must be tables [scenario.NAME] of options", None, "scenario")
    options: dict[str, dict[str, Any]] = {}
    for s, opts in options_t.items():
        if not isinstance(opts, dict):
            raise w.error(f"[scenario.{s}] must be a table of options", "scenario", s)
        if s not in scenarios:
            raise w.error(f"options for scenario {s!r}, which the sweep does not run",
                          f"scenario.{s}")
        try:
            check_options(s, opts)
        except ValueError as exc:
            bad = getattr(exc, "key", None)
            raise w.error(str(exc), f"scenario.{s}", bad) from None
        options[s] = opts

    # controllers and agents
    slots: dict[str, list[dict[str, Any]]] = {}
    for kind in ("controllers", "agents"):
        items = data.get(kind, [])
        if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
            raise w.error(f"{kind} must be [[{kind}]] tables", None, kind)
        names = []
        for k, item in enumerate(items):
            nm = item.get("name")
            if not isinstance(nm, str) or not nm:
                raise w.error(f"[[{kind}]] #{k + 1} needs a name", kind, None, k)
            if nm in names:
                raise w.error(f"[[{kind}]] name {nm!r} used twice", kind, "name", k)
            names.append(nm)
        slots[kind] = items
    for s in scenarios:
        needs = get_scenario(s).needs
        if needs == "controller" and not slots["controllers"]:
            raise w.error(f"scenario {s!r} needs at least one [[controllers]] table",
                          "sweep", "scenarios")
        if needs == "agent" and not slots["agents"]:
            raise w.error(f"scenario {s!r} needs at least one [[agents]] table",
                          "sweep", "scenarios")
    for kind, needs in (("controllers", "controller"), ("agents", "agent")):
        if slots[kind] and not any(get_scenario(s).needs == needs for s in scenarios):
            raise w.error(f"[[{kind}]] given but no scenario uses them", kind)
    for kind, needs in (("controllers", "controller"), ("agents", "agent")):
        for k, item in enumerate(slots[kind]):
            for s in scenarios:
                sc = get_scenario(s)
                if sc.needs == needs and sc.check_slot is not None:
                    try:
                        sc.check_slot(item)
                    except ValueError as exc:
                        bad = getattr(exc, "key", None)
                        raise w.error(f"[[{kind}]] {item['name']!r}: {exc}", kind, bad,
                                      k) from None

    return SweepSpec(path=path, text=text, name=name, presets=list(presets),
                     scenarios=list(scenarios), seeds=list(seeds), spreads=spreads, grid=grid,
                     options=options, controllers=slots["controllers"], agents=slots["agents"],
                     quick=q, summary_dir=summary_dir, description=description,
                     preset_files=files)


def _flatten(table: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{"compliance": {"stiffness": 0.3}}`` and ``{"compliance.stiffness": 0.3}`` alike."""
    out: dict[str, Any] = {}
    for k, v in table.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flatten(v, key + "."))
        else:
            out[key] = v
    return out
