"""Summaries of a sweep: a markdown table and a figure from ``results.csv``.

Per scenario, every metric is reduced to n / mean / std / min / max over the
rows of each (preset, controller) group, i.e. over seeds, randomized drives
and grid points together. Written to ``DIR/summary.md`` and
``DIR/summary.png``, and to ``<summary_dir>/<name>.md/.png`` when the spec
sets ``summary_dir`` or ``hdgym sweep --summary-dir DIR`` asks for it.
"""

from __future__ import annotations

import math
import shutil
import tomllib
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from hdgym.files import atomic_write_text
from hdgym.page_changes import moved_section
from hdgym.sweep.backends import FIXED_COLUMNS
from hdgym.sweep.store import read_rows

__all__ = ["group_stats", "summarize"]

MAX_PANELS = 12


def _float(s: str) -> float:
    try:
        return float(s)
    except ValueError:
        return math.nan


def metric_columns(header: list[str]) -> list[str]:
    return [c for c in header if c not in FIXED_COLUMNS and not c.startswith("param:")]


def group_stats(rows: list[dict[str, str]], header: list[str]
                ) -> dict[str, dict[tuple[str, str], dict[str, dict[str, float]]]]:
    """``{scenario: {(preset, controller): {metric: {n, mean, std, min, max}}}}`` over ok rows."""
    groups: dict[str, dict[tuple[str, str], dict[str, list[float]]]] = defaultdict(
        lambda: defaultdict(lambda: defaultdict(list)))
    metrics = metric_columns(header)
    for r in rows:
        if r.get("status") != "ok":
            continue
        g = groups[r["scenario"]][(r["preset"], r["controller"])]
        for m in metrics:
            v = _float(r.get(m, ""))
            if math.isfinite(v):
                g[m].append(v)
    out: dict[str, dict[tuple[str, str], dict[str, dict[str, float]]]] = {}
    for scen in sorted(groups):
        out[scen] = {}
        for key in sorted(groups[scen]):
            stats = {}
            for m, vals in groups[scen][key].items():
                a = np.asarray(vals)
                stats[m] = {"n": float(a.size), "mean": float(a.mean()),
                            "std": float(a.std(ddof=1)) if a.size > 1 else math.nan,
                            "min": float(a.min()), "max": float(a.max())}
            out[scen][key] = stats
    return out


def _scenario_doc(name: str) -> str:
    """First paragraph of a scenario's docstring (says what the metrics are, in SI)."""
    try:
        from hdgym.sweep.scenarios import get_scenario

        fn = get_scenario(name).fn
    except Exception:  # noqa: BLE001 - the summary must not fail on a missing package
        return ""
    doc = (fn.__doc__ or "").strip().split("\n\n")
    return " ".join(line.strip() for line in doc[0].splitlines()) if doc else ""


def _fmt(v: float) -> str:
    if not math.isfinite(v):
        return "–"
    return f"{v:.4g}"


def summarize(out_dir: str | Path, *, command: str | None = None,
              dest: str | Path | None = None) -> Path:
    """Write the summary of ``out_dir/results.csv``; return the markdown path.

    Args:
        out_dir: a sweep output directory (``results.csv``, ``spec.toml``).
        command: the command that regenerates it (named in the markdown).
        dest: also copy to ``dest/<name>.md/.png`` (default: the spec's
            ``summary_dir``, if any).
    """
    out_dir = Path(out_dir)
    header, rows = read_rows(out_dir / "results.csv")
    spec: dict[str, Any] = {}
    if (out_dir / "spec.toml").exists():
        spec = tomllib.loads((out_dir / "spec.toml").read_text()).get("sweep", {})
    name = spec.get("name", out_dir.name)
    if dest is None and spec.get("summary_dir"):
        dest = spec["summary_dir"]
    command = command or f"hdgym sweep {out_dir / 'spec.toml'} --out {out_dir}"
    stats = group_stats(rows, header)

    n_err = sum(r.get("status") != "ok" for r in rows)
    quick = sorted({r.get("quick", "") for r in rows})
    seeds = sorted({r.get("seed", "") for r in rows}, key=lambda s: int(s) if s.isdigit() else 0)
    versions = sorted({r.get("hdgym_version", "") for r in rows})
    elapsed = [_float(r.get("elapsed_s", "")) for r in rows]
    lines = [
        f"# Sweep `{name}`",
        "",
        f"Regenerate: `{command}`",
        "",
    ]
    if spec.get("description"):
        lines += [spec["description"].strip(), ""]
    lines += [
        f"{len(rows)} jobs ({n_err} failed), seeds {', '.join(seeds) or '–'}, "
        f"quick = {'/'.join(quick) or '–'}, hdgym {', '.join(versions) or '–'}; "
        f"job time {np.nansum(elapsed):.1f} s total, "
        f"{np.nanmedian(elapsed) if elapsed else math.nan:.3g} s median.",
        "",
    ]
    params = [c for c in header if c.startswith("param:")]
    if params:
        lines += ["Varied per job: " + ", ".join(f"`{c[6:]}`" for c in params)
                  + " (drawn values in `results.csv`).", ""]
    lines += ["Statistics over seeds, randomized drives and grid points of each "
              "(preset, controller) group; std is the sample standard deviation.", ""]
    for scen, groups in stats.items():
        lines += [f"## {scen}", ""]
        doc = _scenario_doc(scen)
        if doc:
            lines += [doc, ""]
        lines += ["| preset | controller | metric | n | mean | std | min | max |",
                  "|---|---|---|---:|---:|---:|---:|---:|"]
        for (preset, ctrl), ms in groups.items():
            for m, s in ms.items():
                lines.append(f"| {preset} | {ctrl or '–'} | {m} | {int(s['n'])} | "
                             f"{_fmt(s['mean'])} | {_fmt(s['std'])} | {_fmt(s['min'])} | "
                             f"{_fmt(s['max'])} |")
        lines.append("")
    errors = [r for r in rows if r.get("status") != "ok"]
    if errors:
        lines += ["## Failed jobs", "",
                  "| job_id | preset | scenario | controller | seed | error |",
                  "|---|---|---|---|---|---|"]
        for r in errors[:50]:
            err = r.get("error", "").replace("|", "/")[:200]
            lines.append(f"| {r['job_id']} | {r['preset']} | {r['scenario']} | "
                         f"{r['controller'] or '–'} | {r['seed']} | {err} |")
        if len(errors) > 50:
            lines.append(f"\n… and {len(errors) - 50} more (see results.csv).")
        lines.append("")
    # the page this run replaces: the committed copy if there is one, else the run's own
    previous = Path(dest) / f"{name}.md" if dest is not None else out_dir / "summary.md"
    if not previous.is_file():
        previous = out_dir / "summary.md"
    moved = moved_section(previous, "\n".join(lines))
    if moved:
        lines += [moved]
    lines += ["![summary](summary.png)" if dest is None else f"![summary]({name}.png)", ""]

    md = out_dir / "summary.md"
    png = out_dir / "summary.png"
    _figure(stats, png, name)
    atomic_write_text(md, "\n".join(lines).replace(f"]({name}.png)", "](summary.png)"))
    if dest is not None:
        d = Path(dest)
        d.mkdir(parents=True, exist_ok=True)
        atomic_write_text(d / f"{name}.md", "\n".join(lines))
        shutil.copyfile(png, d / f"{name}.png")
        return d / f"{name}.md"
    return md


def _figure(stats: dict[str, dict[tuple[str, str], dict[str, dict[str, float]]]],
            path: Path, name: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = []
    for scen, groups in stats.items():
        metrics = sorted({m for ms in groups.values() for m in ms})
        panels += [(scen, m) for m in metrics]
    panels = panels[:MAX_PANELS]
    n = max(len(panels), 1)
    cols = min(3, n)
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), squeeze=False)
    for ax in axes.flat[len(panels):]:
        ax.set_visible(False)
    for ax, (scen, metric) in zip(axes.flat, panels, strict=False):
        groups = stats[scen]
        presets = sorted({p for p, _ in groups})
        ctrls = sorted({c for _, c in groups})
        width = 0.8 / max(len(ctrls), 1)
        for j, c in enumerate(ctrls):
            xs, mean, std, lo, hi = [], [], [], [], []
            for i, p in enumerate(presets):
                s = groups.get((p, c), {}).get(metric)
                if s is None:
                    continue
                xs.append(i + (j - (len(ctrls) - 1) / 2) * width)
                mean.append(s["mean"])
                std.append(0.0 if not math.isfinite(s["std"]) else s["std"])
                lo.append(s["min"])
                hi.append(s["max"])
            if not xs:
                continue
            ax.bar(xs, mean, width * 0.9, yerr=std, capsize=3, label=c or "open loop",
                   alpha=0.8)
            ax.vlines(xs, lo, hi, colors="0.45", linewidth=0.8, linestyles=":")
            ax.plot(xs, lo, "^", xs, hi, "v", color="0.45", markersize=3)
        ax.set_xticks(range(len(presets)), presets, rotation=15, fontsize=7)
        ax.set_title(f"{scen}: {metric}", fontsize=8)
        ax.tick_params(axis="y", labelsize=7)
        if len(ctrls) > 1:
            ax.legend(fontsize=6)
    fig.suptitle(f"sweep {name}: mean ± std (bars, error bars), min–max (grey triangles)",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
