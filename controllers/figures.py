"""Figures of the controller benchmark page: one set per joint, PNG files."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np


def _save(fig: Any, figdir: Path, filename: str) -> str:
    """Write a figure into ``figdir``; return its path relative to the page."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(figdir / filename, dpi=110)
    plt.close(fig)
    return f"controllers/{filename}"


def figures(name: str, res: dict[str, Any], figdir: Path) -> dict[str, str]:
    """Tracking, load-step, point-to-point and Bode figures of one joint's results (the
    dict :mod:`controllers.benchmark` gathers) into ``figdir``; their paths relative to
    the page, by experiment."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figdir.mkdir(parents=True, exist_ok=True)
    files = {}
    deg = 180 / math.pi

    tr = res["tracking"][res["primary"]]
    fig, ax = plt.subplots(3, 1, figsize=(8, 9))
    for k, r in tr["runs"].items():
        t = r.time
        win = t >= t[-1] - 4.0
        ax[0].plot(t[win], r.error[win] * deg * 3600, label=k, lw=0.8)
    ax[0].set(xlabel="time (s)", ylabel="output error (arcsec)",
              title=f"{name}: {tr['wg_rev_s']} WG rev/s, last 4 s")
    ax[0].legend(fontsize=7)
    conv = np.array(tr["convergence"])
    ax[1].semilogy(conv[:, 0], conv[:, 2] * deg * 3600, "o-", label="PID")
    ax[1].semilogy(conv[:, 0], conv[:, 1] * deg * 3600, "o-", label="PID + repetitive")
    ax[1].set(xlabel="time (s)", ylabel="RMS error per 2 s (arcsec)",
              title="repetitive control convergence")
    ax[1].legend(fontsize=7)
    for k, r in tr["sweep_runs"].items():
        ax[2].plot(r.time, r.error * deg * 3600, label=k, lw=0.8)
    ax[2].set(xlabel="time (s)", ylabel="output error (arcsec)",
              title="speed sweep with the learnt series kept")
    ax[2].legend(fontsize=7)
    files["tracking"] = _save(fig, figdir, f"tracking_{name}.png")

    ls = res["load_step"]
    fig, ax = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for k, r in ls["runs"].items():
        ax[0].plot(r.time, -r.error * deg * 3600, label=k, lw=0.8)
        ax[1].plot(r.time, r.record.columns["current_command"], label=k, lw=0.8)
    ax[0].set(ylabel="output deviation (arcsec)", title=f"{name}: load step {ls['step']:.3g} N m")
    ax[1].set(xlabel="time (s)", ylabel="current command (A)")
    ax[0].legend(fontsize=7)
    files["load_step"] = _save(fig, figdir, f"load_step_{name}.png")

    pp = res["point_to_point"]
    fig, ax = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    for k, r in pp["runs"].items():
        ax[0].plot(r.time, r.output_angle * deg, label=k, lw=0.8)
        ax[1].plot(r.time, r.error * deg, label=k, lw=0.8)
        ax[2].plot(r.time, r.record.columns["current_command"], label=k, lw=0.8)
    r0 = next(iter(pp["runs"].values()))
    ax[0].plot(r0.time, r0.reference * deg, "k--", lw=0.8, label="reference")
    ax[0].set(ylabel="output angle (deg)", title=f"{name}: point-to-point move")
    ax[1].set(ylabel="error (deg)")
    ax[2].set(xlabel="time (s)", ylabel="current command (A)")
    ax[0].legend(fontsize=7)
    files["point_to_point"] = _save(fig, figdir, f"point_to_point_{name}.png")

    bd = res["bode"]
    fig, ax = plt.subplots(2, 2, figsize=(10, 6))
    for j, (ch, d) in enumerate(bd["channels"].items()):
        k = (d["f"] >= 0.5) & (d["f"] <= 200)
        ax[0, j].semilogx(d["f"][k], 20 * np.log10(np.abs(d["h"][k])), label="simulated (H1)")
        ax[0, j].semilogx(d["f"][k], 20 * np.log10(np.abs(d["model"][k])), "--",
                          label="linear model")
        ax[1, j].semilogx(d["f"][k], np.degrees(np.unwrap(np.angle(d["h"][k]))))
        ax[1, j].semilogx(d["f"][k], np.degrees(np.unwrap(np.angle(d["model"][k]))), "--")
        for a in ax[:, j]:
            a.axvline(bd["fmax"], color="grey", lw=0.6)
        ax[0, j].set(title=f"{name}: current → {ch}", ylabel="dB")
        ax[1, j].set(xlabel="Hz", ylabel="deg")
        ax[0, j].legend(fontsize=7)
    files["bode"] = _save(fig, figdir, f"bode_{name}.png")
    return files
