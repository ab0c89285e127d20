"""Benchmarks behind ``hdgym bench``: throughput as ratios against references
measured in the same run, written to ``results/bench.md``.

No benchmark here asserts a time: machines are shared and noisy. Each row
states the measured value, the reference measured right beside it, and the
target the issue set.

Sections come from a registry (:func:`register_section`): hdgym's own
(environments, discrepancy workflow) and those of the packages built on it,
found through the entry-point group ``hdgym.bench_sections``
(:mod:`hdgym.plugins`; ``agents`` adds Stable-Baselines3 training). hdgym
imports none of those packages itself.
"""

from __future__ import annotations

import os
import platform
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numba as nb
import numpy as np

from hdgym import plugins
from hdgym.effects import flags_of
from hdgym.files import atomic_write_text
from hdgym.page_changes import moved_section
from hdgym.params import JointParams, preset
from hdgym.physics import kernel
from hdgym.physics import layout as L
from hdgym.physics.lanes import PARALLEL_THRESHOLD, LaneBatch
from hdgym.progress import bar

#: a bench section: ``fn(quick) -> rows`` (one dict per row, as :func:`write_report` reads)
SectionFn = Callable[[bool], list[dict]]


@dataclass(frozen=True)
class Section:
    """A titled table of the bench page; sections are written by ``order``, then title."""

    title: str
    fn: SectionFn
    order: float


_SECTIONS: dict[str, Section] = {}


def register_section(title: str, order: float = 50.0) -> Callable[[SectionFn], SectionFn]:
    """Decorator: ``fn(quick) -> rows`` becomes the bench section ``title``.

    hdgym's own sections use orders 10 (physics), 20 (environments) and 40
    (discrepancy workflow); the soak runs (``--soak``) come after every section.
    """

    def deco(fn: SectionFn) -> SectionFn:
        _SECTIONS[title] = Section(title, fn, float(order))
        return fn

    return deco


def sections() -> tuple[list[Section], dict[str, str]]:
    """The registered sections in page order, and the entry points that failed to load
    (``{name: why}``: their sections are not measured)."""
    failed = plugins.load(plugins.BENCH_SECTIONS)
    return sorted(_SECTIONS.values(), key=lambda sec: (sec.order, sec.title)), failed


@register_section("Gymnasium environments", order=20)
def _envs(quick: bool) -> list[dict]:
    from hdgym.envs.bench import bench_envs

    return bench_envs(quick)


@register_section("Discrepancy workflow", order=40)
def _discrepancy(quick: bool) -> list[dict]:
    from hdgym.discrepancy.bench import bench_diagnose

    return bench_diagnose(quick)


@nb.njit(cache=True, parallel=True, nogil=True)
def _bare_loop(xs: np.ndarray, ps: np.ndarray, i_cmd: np.ndarray, t_ext: np.ndarray, dt: float,
               n_sub: int, flags: np.ndarray, n_steps: int) -> None:
    """The same physics step, all control periods inside one compiled call."""
    for e in nb.prange(xs.shape[0]):
        trig = np.empty(kernel.SCRATCH)
        for _ in range(n_steps):
            kernel.substeps(xs[e], ps[e], i_cmd[e], t_ext[e], dt, n_sub, flags[e], trig)


def best_rate(fn: Callable[[], None], units: float, repeats: int = 3) -> float:
    """Best units/s of ``repeats`` timed calls of ``fn`` (after one warm-up call)."""
    fn()
    best = 0.0
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = max(best, units / (time.perf_counter() - t0))
    return best


def bench_physics(p: JointParams, quick: bool = False) -> list[dict]:
    """Env-steps/s of the compiled steps at 1, 64 and 1,024 envs, stepped from Python
    once per control period: the one-env kernel beside the bare compiled loop of the
    same step, and the SIMD lanes beside the one-env kernel."""
    n_sub = int(p.integration.n_substeps)
    dt = p.integration.ctrl_dt / n_sub
    rows = []
    for n in (1, 64, 1024):
        steps = max(20, (2000 if not quick else 200) * (64 if n == 1 else 1) // max(1, n // 64))
        ps = L.pack_batch(p, n)
        flags = np.full(n, flags_of(p.effects), dtype=np.int64)
        u = np.linspace(1.0, 4.0, n)
        z = np.zeros(n)
        bad = np.zeros(n, dtype=np.bool_)
        step = kernel.step_for(n)
        xs = L.initial_state(ps, flags)

        def stepped(xs=xs, ps=ps, u=u, z=z, flags=flags, bad=bad, step=step, steps=steps):
            for _ in range(steps):
                step(xs, ps, u, z, dt, n_sub, flags, bad)

        xb = xs.copy()

        def bare(xb=xb, ps=ps, u=u, z=z, flags=flags, steps=steps):
            _bare_loop(xb, ps, u, z, dt, n_sub, flags, steps)

        r_step = best_rate(stepped, n * steps)
        r_bare = best_rate(bare, n * steps)
        rows.append({
            "name": f"physics, {n} env{'s' if n > 1 else ''}, one-env kernel stepped from Python",
            "value": r_step, "unit": "env-steps/s", "reference": "bare compiled loop",
            "reference_value": r_bare, "ratio": r_step / r_bare,
            "substeps_per_s": r_step * n_sub, "target": "", "met": None,
        })
        if n == 1:  # a SIMD block would run 63 spare lanes for one env
            continue
        xl = xs.copy()
        batch = LaneBatch(xl, ps, flags, dt, parallel=n >= PARALLEL_THRESHOLD)

        def lanes(batch=batch, xl=xl, u=u, z=z, bad=bad, steps=steps):
            for _ in range(steps):
                batch.step(u, z, n_sub, xl, bad)

        r_lanes = best_rate(lanes, n * steps)
        rows.append({
            "name": f"physics, {n} envs, SIMD lanes stepped from Python",
            "value": r_lanes, "unit": "env-steps/s",
            "reference": "one-env kernel stepped from Python", "reference_value": r_step,
            "ratio": r_lanes / r_step, "substeps_per_s": r_lanes * n_sub,
            "target": "≥ 1,000,000 env-steps/s at 1,024 envs" if n == 1024 else "",
            "met": (r_lanes >= 1e6) if n == 1024 else None,
        })
    return rows


def _fmt(v: float) -> str:
    return f"{v:,.0f}" if v >= 100 else f"{v:.3g}"


def _load() -> str:
    """The 1-minute load average against the cores (other jobs slow the absolute rates)."""
    try:
        return f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"
    except OSError:  # pragma: no cover - no load average on this platform
        return "unknown"


def write_report(tables: dict[str, list[dict]], path: Path, command: str,
                 not_measured: dict[str, str] | None = None,
                 load: tuple[str, str] | None = None) -> None:
    """Write the bench tables as markdown (atomically); ``not_measured`` names the entry
    points whose sections could not be loaded, and why; ``load`` is the machine's load
    average at the start and at the end of the run."""
    lines = [
        "# hdgym benchmarks", "",
        f"Regenerate with `{command}`. Machine: {platform.machine()}, "
        f"{nb.config.NUMBA_NUM_THREADS} numba threads, Python {platform.python_version()}, "
        f"numba {nb.__version__}, numpy {np.__version__}. Every ratio is against a reference "
        "measured in the same run."
        + (f" Load average {load[0]} at the start, {load[1]} at the end: other jobs on the "
           "machine lower the absolute rates more than the ratios." if load else ""), "",
    ]
    lines += [f"Not measured: the sections of `{name}` ({why})." for name, why in
              (not_measured or {}).items()] + ([""] if not_measured else [])
    for title, rows in tables.items():
        lines += [f"## {title}", "", "| benchmark | value | reference | reference value | ratio "
                  "| target | met |", "|---|---|---|---|---|---|---|"]
        for r in rows:
            met = r.get("met")
            lines.append(
                f"| {r['name']} | {_fmt(r['value'])} {r.get('unit', '')} | {r.get('reference', '')}"
                f" | {_fmt(r['reference_value']) if r.get('reference_value') else ''} | "
                f"{r['ratio']:.3g} | {r.get('target', '')} | "
                f"{'' if met is None else ('yes' if met else 'NO')} |"
                if r.get("ratio") is not None else
                f"| {r['name']} | {_fmt(r['value'])} {r.get('unit', '')} | | | | "
                f"{r.get('target', '')} | {'' if met is None else ('yes' if met else 'NO')} |")
        notes = [r["note"] for r in rows if r.get("note")]
        lines += [""] + [f"- {n}" for n in notes] + ([""] if notes else [])
    text = "\n".join(lines) + "\n"
    moved = moved_section(Path(path), text)
    atomic_write_text(path, text + ("\n" + moved if moved else ""))


def bench_soak(quick: bool = False) -> list[dict]:
    """One million control periods per preset (100,000 with ``quick``): bounds and memory."""
    from hdgym.numerics import soak
    from hdgym.params import preset_names

    rows = []
    for name in bar(preset_names(), "soak", unit="preset"):
        r = soak(preset(name), n_steps=100_000 if quick else 1_000_000)
        f, la = r["first"], r["last"]
        rows.append({
            "name": f"soak {name}, {r['steps']:,} steps", "value": r["steps"] / r["seconds"],
            "unit": "steps/s", "ratio": None, "met": r["finite"] and (
                la["motor_velocity"] <= 1.5 * f["motor_velocity"] + 1e-9
                and r["memory_end_mb"] <= r["memory_start_mb"] + 50),
            "target": "finite, bounded, no memory growth",
            "note": (f"{name}: |motor speed| max {f['motor_velocity']:.4g} → "
                     f"{la['motor_velocity']:.4g} rad/s, |torque| max {f['output_torque']:.4g} → "
                     f"{la['output_torque']:.4g} N m, |torsion| max {f['torsion']:.3g} → "
                     f"{la['torsion']:.3g} rad (first → last chunk); memory "
                     f"{r['memory_start_mb']:.0f} → {r['memory_end_mb']:.0f} MiB"),
        })
    return rows


@register_section("Physics step (tuttle-joint1, every effect on)", order=10)
def _physics(quick: bool) -> list[dict]:
    p = preset("tuttle-joint1")
    rows = bench_physics(p, quick)
    for r in rows:
        r["note"] = None
    rows[-1]["note"] = ("substeps/s, stepped from Python: " + ", ".join(
        f"{r['name'].split(',')[1].strip()} {r['name'].split(',')[2].split()[0]} "
        f"{r['substeps_per_s']:,.0f}" for r in rows)
        + f" ({p.integration.n_substeps} substeps per 1 ms control period)")
    return rows


def run(quick: bool = False, out: Path = Path("results/bench.md"),
        soak: bool = False) -> dict[str, list[dict]]:
    """Run every registered section and write the report (``soak`` adds the long soak runs)."""
    registered, failed = sections()
    load_start = _load()
    tables = {sec.title: sec.fn(quick) for sec in bar(registered, "bench", unit="section")}
    if soak:
        tables["Soak (issue: long runs)"] = bench_soak(quick)
    write_report(tables, out, "hdgym bench" + (" --quick" if quick else "")
                 + (" --soak" if soak else "") + f" --out {out}", not_measured=failed,
                 load=(load_start, _load()))
    return tables
