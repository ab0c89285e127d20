"""Seyfferth et al. and the seed-002 Maxwell-slip identification.

(e) the seed-002 Maxwell-slip + two-segment-spring fit on ``wave-drive-50``
    (:mod:`hdgym.identify`), validated on a record with another seed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hdgym.params import preset
from hdgym.reproduce.common import Item, Paper, finish, plt_module, simulator


def check_identification(out: Path, quick: bool) -> Item:
    """(e) Maxwell-slip + two-segment spring fit on wave-drive-50 (seed 002)."""
    from hdgym.identify import fit_maxwell_slip, nmse

    item = Item("e", "Maxwell-slip identification (seed 002), wave-drive-50",
                "locked output, random current; fit four Maxwell-slip elements + two-segment "
                "spring to (motor_angle/ratio, output_torque) of one seed; NMSE on a validation "
                "record with another seed < 1 %")
    p = preset("wave-drive-50")
    sim = simulator(p, locked_output=True)
    duration = 10.0 if quick else 30.0
    # RMS current for about half the drive's peak-torque range at low frequency
    amp = 0.35 * p.amplifier.current_limit
    spec = f"random:{amp!r}:5"
    tr = sim.run(spec, duration, seed=1)
    va = sim.run(spec, duration, seed=2)
    fit = fit_maxwell_slip(tr.motor_angle / p.ratio, tr.output_torque, n_elements=4)
    xv = va.motor_angle / p.ratio
    yv_hat = fit.predict(xv)
    e_val = nmse(yv_hat, va.output_torque)
    good = e_val < 1.0
    item.measured.append(f"random current RMS {amp:.3g} A, 5 Hz cutoff, {duration:.0f} s; "
                         f"training seed 1 NMSE {fit.nmse:.3f} %, validation seed 2 NMSE "
                         f"{e_val:.3f} % {'PASS' if good else 'FAIL'}")
    item.measured.append(
        f"fitted k1 {fit.k1:.4g}, k0 {fit.k0:.4g} N m/rad, theta0 {fit.theta0:.3g} rad; kappa "
        + ", ".join(f"{k:.4g}" for k in fit.kappa) + " N m/rad; W "
        + ", ".join(f"{w:.3g}" for w in fit.strength) + " N m")
    item.passed = bool(good)
    plt = plt_module()
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    t = va.time
    sel = t < min(5.0, t[-1])
    axes[0].plot(t[sel], va.output_torque[sel], lw=0.8, label="validation data (seed 2)")
    axes[0].plot(t[sel], yv_hat[sel], lw=0.8, ls="--", label="fitted model")
    axes[0].set_xlabel("time (s)")
    axes[0].set_ylabel("torque (N m)")
    axes[0].set_title(f"wave-drive-50 validation: NMSE {e_val:.3f} %")
    axes[0].legend(fontsize=8)
    axes[1].plot(np.degrees(xv), va.output_torque, lw=0.5, label="validation data")
    axes[1].plot(np.degrees(xv), yv_hat, lw=0.5, ls="--", label="fitted model")
    axes[1].set_xlabel("torsion motor_angle/ratio (output °)")
    axes[1].set_ylabel("torque (N m)")
    axes[1].legend(fontsize=8)
    return finish(item, fig, out / "identification.png", item.passed)



PAPER = Paper("seyfferth", "Seyfferth et al. and seed 002: hysteresis identification",
              ("wave-drive-50",), (check_identification,))
