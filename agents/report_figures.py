"""Figures of ``results/rl/`` (:mod:`agents.report`): the front, one episode, learning."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import numpy as np

from agents.common import load_policy
from agents.families import label
from agents.front import best_classical, controller, success, uncut

#: one colour per family in every panel (``<family>+ke`` dashed in its family's colour)
COLORS = {"const": "tab:blue", "pi": "tab:orange", "pi_ramp": "tab:green", "damp": "tab:red",
          "damp_full": "tab:purple", "damp_enc": "tab:pink", "two_phase": "tab:brown"}
#: the figure's deadlines
FIG_DEADLINES = (1.5, 2.0, 2.5, 3.0)


def front_figure(fronts: dict[str, Any], pol: dict[str, dict[str, np.ndarray]],
                 out: Path, rating: float,
                 panels: dict[str, tuple[float, ...]] | None = None) -> None:
    """Success against torque cap, one panel per (variant, deadline); ``rating`` N m;
    ``panels``: a variant's deadlines (s) where not :data:`FIG_DEADLINES`."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(fronts)
    panels = panels or {}
    ncol = max([len(FIG_DEADLINES)] + [len(v) for v in panels.values()])
    fig, axes = plt.subplots(len(names), ncol, figsize=(4 * ncol,
                             3.2 * len(names)), sharex=True, sharey=True, squeeze=False)
    for r, var in enumerate(names):
        f = fronts[var]
        cols = panels.get(var, FIG_DEADLINES)
        for ax in axes[r][len(cols):]:
            ax.set_visible(False)
        for c, d in enumerate(cols):
            ax = axes[r][c]
            if d not in f["deadlines"]:
                ax.set_visible(False)
                continue
            i = f["deadlines"].index(d)
            for fam, v in f["families"].items():
                base = fam.partition("+")[0]
                ax.plot(f["caps"], [100 * e["test"] for e in v["front"][i]],
                        label=label(fam), lw=1.2, color=COLORS.get(base, "tab:gray"),
                        ls="--" if "+" in fam else "-")
            if var in pol:
                p = pol[var]
                ax.plot(f["caps"], [100 * success(p["time_to_target"], p["peak_torque"], cap,
                                                  d).mean() for cap in f["caps"]],
                        "k", lw=2.2, label="PPO policy")
            ax.axvline(rating, color="grey", ls=":", lw=1)
            ax.set_title(f"{var.replace('HarmonicDrive', '')}\ndeadline {d:g} s", fontsize=9)
            ax.grid(alpha=0.3)
            if c == 0:
                ax.set_ylabel("success, held-out (%)")
            if r == len(names) - 1:
                ax.set_xlabel("torque cap R (N m)")
    for row in axes:
        row[0].legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)


def speed_figure(var: str, cfg: dict[str, Any], deadline: float, zip_path: Path,
                 front: dict[str, Any], out: Path, rating: float, seed: int) -> str:
    """One held-out episode of variant ``var`` (env config ``cfg``): the policy in
    ``zip_path``, the best tuned classical pick at (``rating``, ``deadline``) and full
    current (speed, flexspline torque, current against time)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from agents.baselines import ConstantCurrent
    from agents.evaluate import run_episodes

    cfg = uncut(cfg)
    fam, best = best_classical(front, rating, deadline)
    runs = {"PPO policy": run_episodes(cfg, load_policy(zip_path), 1, seed,
                                       int(cfg["env"]["action_repeat"])),
            f"{label(fam)} (tuned)": run_episodes(
                cfg, controller(cfg, fam, {k: np.asarray([v]) for k, v in best["point"].items()}),
                1, seed),
            "constant full current": run_episodes(cfg, ConstantCurrent(1.0), 1, seed)}
    fig, ax = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    for name, tr in runs.items():
        t = tr["time"]
        ax[0].plot(t, np.degrees(tr["speed"][0]), lw=0.8, label=name)
        ax[1].plot(t, tr["torque"][0], lw=0.6)
        ax[2].plot(t, tr["current"][0], lw=0.6)
    ax[0].axhline(np.degrees(runs["PPO policy"]["target"][0]), color="k", ls=":", lw=1)
    for a in ax:
        a.axvline(deadline, color="grey", ls="--", lw=1)
        a.grid(alpha=0.3)
    for sign in (1, -1):
        ax[1].axhline(sign * rating, color="r", ls=":", lw=1)
    ax[0].set_ylabel("motor speed (deg/s)")
    ax[1].set_ylabel("flexspline torque (N m)")
    ax[2].set_ylabel("motor current (A)")
    ax[2].set_xlabel("time (s)")
    ax[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return (f"`{out.name}`: held-out episode {seed} of `{var}` (no cut at the rating, so the "
            "whole run shows): the policy, the best tuned classical controller at the rating "
            "and deadline, and constant full current; dotted: the target and the rating, "
            "dashed: the deadline.")


def learning_curve(run: Path | None, out: Path) -> str:
    """Training success and return against episodes from the run's VecMonitor file."""
    if run is None or not (run / "monitor" / "native.monitor.csv").is_file():
        return ""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    text = (run / "monitor" / "native.monitor.csv").read_text().splitlines()
    rows = list(csv.DictReader(text[1:]))  # line 0 is the monitor's JSON header
    if not rows:
        return "Learning curve: no training episode finished in this run."
    ret = np.array([float(r["r"]) for r in rows])
    ok = np.array([r.get("is_success") == "True" for r in rows], dtype=float)
    t = np.array([float(r["t"]) for r in rows])
    w = max(len(ret) // 40, 1)
    k = np.ones(w) / w
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.2))
    ax[0].plot(t, ret, ".", ms=2, alpha=0.3)
    ax[0].plot(t[w - 1:], np.convolve(ret, k, "valid"))
    ax[0].set(xlabel="wall time (s)", ylabel="episode return")
    ax[1].plot(t[w - 1:], 100 * np.convolve(ok, k, "valid"))
    ax[1].set(xlabel="wall time (s)", ylabel=f"success, last {w} episodes (%)")
    for a in ax:
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    plt.close(fig)
    with (out.with_suffix(".csv")).open("w", newline="") as fh:
        wr = csv.writer(fh)
        wr.writerow(["wall_time_s", "episode_return", "success"])
        wr.writerows(zip(t.round(2), ret.round(3), ok.astype(int), strict=True))
    return (f"Learning curve: `{out.name}` (training episodes from the run's VecMonitor file; "
            f"data in `{out.with_suffix('.csv').name}`).")
