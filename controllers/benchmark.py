"""Controller benchmark: ``hdgym controllers [--quick]`` → ``controllers.md`` + figures.

On ``tuttle-joint1`` and ``tuttle-joint3`` with every effect on, amplifier
limits and quantized encoders (``Simulator(sensors=True)``), runs the four
experiments of :mod:`controllers.experiments` (slow tracking with PID, KE
feedforward and repetitive control; a load step with and without a
disturbance observer; a point-to-point move; the linear model against the
simulated response), draws them (:mod:`controllers.figures`) and writes the
page (:mod:`controllers.report`).

Errors are computed on the *true* output angle (re-simulated from the
recorded current; see :mod:`controllers.scenarios`); the controllers only
ever see the sensors. The PID is designed with python-control
(:func:`controllers.scenarios.motor_pid`), the same for every row.

The same experiments run one controller config at a time for ``hdgym sweep``
(:mod:`controllers.sweep`; spec ``hdgym/sweep/specs/controllers.toml``).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from controllers.experiments import (
    JOINTS,
    PRIMARY,
    SPEEDS,
    bode,
    load_step,
    point_to_point,
    settings,
    tracking,
)
from controllers.figures import figures
from controllers.report import markdown
from hdgym.files import atomic_write_text
from hdgym.page_changes import moved_section
from hdgym.params import preset
from hdgym.progress import bar, step


def run(out: Path, quick: bool = False) -> dict[str, Any]:
    """Run the benchmark; write ``out/controllers.md`` and ``out/controllers/*.png``.

    Returns a plain summary per joint (RMS errors in output rad, reductions in
    percent, load-step and point-to-point metrics, Bode errors).
    """
    t0 = time.time()
    out = Path(out)
    cfg = settings(quick)
    results: dict[str, Any] = {}
    with bar(total=len(JOINTS) * (len(SPEEDS) + 4), desc="controllers", unit="run") as b:
        for name in JOINTS:
            p = preset(name)
            track = {}
            for rev in SPEEDS:
                track[rev] = tracking(p, cfg, rev, sweep_too=rev == PRIMARY[name])
                step(b, f"{name} tracking")
            res = {"cfg": cfg, "primary": PRIMARY[name], "tracking": track}
            for key, fn in (("load_step", load_step), ("point_to_point", point_to_point),
                            ("bode", bode)):
                res[key] = fn(p, cfg)
                step(b, f"{name} {key}")
            res["figures"] = figures(name, res, out / "controllers")
            step(b, f"{name} figures")
            results[name] = res
    text = markdown(results, quick, time.time() - t0, out)
    text += moved_section(out / "controllers.md", text)
    out.mkdir(parents=True, exist_ok=True)
    atomic_write_text(out / "controllers.md", text)
    return summary(results)


def summary(results: dict[str, Any]) -> dict[str, Any]:
    """The numbers of a benchmark run without the time series."""
    out: dict[str, Any] = {}
    for name, res in results.items():
        ls, pp, bd = res["load_step"], res["point_to_point"], res["bode"]
        out[name] = {
            "tracking_rms": {rev: dict(t["rms"]) for rev, t in res["tracking"].items()},
            "tracking_reduction_pct": {rev: dict(t["reduction"])
                                       for rev, t in res["tracking"].items()},
            "primary_speed": res["primary"],
            "sweep_rms": dict(res["tracking"][res["primary"]]["sweep_rms"]),
            "load_step": {k: dict(v) for k, v in ls["metrics"].items()},
            "load_step_reduction_pct": ls["reduction"],
            "point_to_point": {k: dict(v) for k, v in pp["metrics"].items()},
            "bode": {k: {"max_db": v["max_db"], "max_deg": v["max_deg"]}
                     for k, v in bd["channels"].items()},
        }
    return out
