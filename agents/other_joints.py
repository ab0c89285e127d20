"""Is there a rated task on Tuttle's joints 2 and 3? Constant-current steps through their traps.

:func:`other_joints` writes the last section of ``results/rl/evaluation.md``
(:mod:`agents.report`): a variant is registered only where crossing the trap
costs torque, so that a rating and a deadline trade against each other as on
joint 1.
"""

from __future__ import annotations

import math

import numpy as np

from agents.common import load_config
from agents.front import run_grid

#: other joints: (preset, constant currents in A from Tuttle's step ranges to the amplifier's
#: limit); targets above their 2x-order traps near 10,000 deg/s
OTHER_JOINTS = (("tuttle-joint2", (1.4, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5)),
                ("tuttle-joint3", (0.28, 0.35, 0.4, 0.45, 0.5, 0.6)))
OTHER_TARGET_DEG_S = (12_000.0, 14_000.0)


def other_joints(n: int, seed: int) -> str:
    """Constant current steps on joints 2 and 3 (``n`` episodes, env seeds ``seed + k``):
    is there a trap, and does crossing it cost torque (the trade-off the task needs)?"""
    verdicts = []
    lines = [f"{n} held-out episodes per row.", "",
             "| joint | constant current (A) | reached (of episodes) | mean time to target (s) "
             "| peak flexspline torque mean / max (N m) |", "|---|---|---|---|---|"]
    for name, levels in OTHER_JOINTS:
        cfg = load_config("resonance_ppo")
        kw = cfg["env"]["kwargs"]
        kw["preset"] = name
        kw["target_speed"] = [math.radians(v) for v in OTHER_TARGET_DEG_S]
        res = run_grid(cfg, "const", [{"level": lv} for lv in levels],
                       list(range(seed, seed + n)))
        for lv, t, p in zip(levels, res["time_to_target"], res["peak_torque"], strict=True):
            ok = np.isfinite(t)
            tt = f"{t[ok].mean():.2f}" if ok.any() else "-"
            lines.append(f"| {name} | {lv:g} | {100 * ok.mean():.0f} % | {tt} | {p.mean():.0f} / "
                         f"{p.max():.0f} |")
        reach = np.isfinite(res["time_to_target"]).mean(axis=1)
        peaks = res["peak_torque"].mean(axis=1)
        trapped = [lv for lv, r in zip(levels, reach, strict=True) if r < 0.5]
        crossing = reach >= 0.95
        verdicts.append(
            f"{name}: trapped (reached in < 50 %) at {', '.join(f'{v:g}' for v in trapped)} A"
            if trapped else f"{name}: no current tried stays trapped")
        if not crossing[-1]:
            verdicts[-1] += "; full current does not cross in >= 95 %: no task by a deadline"
        elif peaks[-1] <= 1.25 * peaks[crossing].min():
            verdicts[-1] += (f"; full current crosses fastest with a peak of {peaks[-1]:.0f} "
                             f"N m against {peaks[crossing].min():.0f} N m for the gentlest "
                             "current that crosses: no torque-time trade-off for a rating")
        else:
            verdicts[-1] += (f"; crossing faster costs torque ({peaks[crossing].min():.0f} to "
                             f"{peaks[-1]:.0f} N m mean peak): a candidate for a rated variant")
    return "\n".join(lines) + "\n\n" + ".\n".join(verdicts) + ".\n"
