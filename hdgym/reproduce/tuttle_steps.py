"""Tuttle (1992) §2.6: the current-step experiments of joints 1-3, one function per item.

Each joint gets 4 s current steps from rest over the current range Tuttle used;
the mean WG speed of the last 2 s and the flexspline torque (his torque sensor)
are compared with his text:

(T2) joint 1: a plateau over 2.8-4.0 A near 8,000 °/s, a jump above it, and
     none of that without the load-dependent tooth friction (his model 4);
(T3) joint 1's torque sensor at that plateau: oscillating around zero,
     reaching about 80 N m;
(T4) joint 2: resonant plateau near 10,000 °/s and a lesser resonant area near
     20,000 °/s;
(T5) joint 3: resonant areas near 5,000, 10,000 and 20,000 °/s, run through, the
     top step beyond 15,000 °/s.

The figures use Tuttle's axes (input velocity or torque against time, figs
D.x.2 and D.1.7) beside the speed-current table and the run-up curve.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hdgym.params import JointParams, preset
from hdgym.reproduce.analysis import (
    PlateauResult,
    RunUp,
    StepRuns,
    grows_smoothly,
    plateau_jump,
    plateau_near,
    run_up,
    step_runs,
)
from hdgym.reproduce.common import Item, finish, plt_module, within

#: Tuttle §2.6 step currents, A: joint 1 by 0.4 A (his 2.8, 3.2, ... 4.0 A), joints 2
#: and 3 over the ranges he used (1.4-4.5 A, 0.28-0.60 A) on a finer grid
STEP_CURRENTS = tuple(np.round(np.arange(1.6, 6.0 + 1e-9, 0.4), 2))
CURRENTS_2 = (*np.round(np.arange(1.4, 4.4 + 1e-9, 0.2), 2), 4.5)
CURRENTS_3 = tuple(np.round(np.arange(0.28, 0.60 + 1e-9, 0.02), 3))
#: wave-generator speed of the joint-1 2x-order resonance, °/s (Tuttle §2.6 p. 87)
PLATEAU_SPEED_DEG = 8000.0
#: resonance speeds and plateau speed tolerance (issue 12: ±15 %)
SPEED_TOL = 0.15
#: a resonant area: the run-up level stands this much above the higher flanking minimum
PROMINENCE = 1.3
#: torque-sensor band at the joint-1 plateau, N m: mean within ±10, peak 60-110
TORQUE_MEAN_TOL = 10.0
TORQUE_PEAK_BAND = (60.0, 110.0)


def torque_mean_ok(worst: float) -> bool:
    """T3's first criterion on the largest |mean torque| over the plateau currents, N m."""
    return bool(abs(worst) <= TORQUE_MEAN_TOL)


def torque_peak_ok(top: float) -> bool:
    """T3's second criterion on the largest |torque| over the plateau currents, N m."""
    return bool(TORQUE_PEAK_BAND[0] <= top <= TORQUE_PEAK_BAND[1])

P87 = "§2.6 p. 87"
J1_SPEEDS = ("two separate resonances can be observed at input speeds of around 4000 and 8000 "
             f"degrees/second ({P87})")
J1_PLATEAU = ("current commands ranging from 2.8 to 4.0 amps all produce the same final "
              "velocity in the second resonance regime (§2.6 p. 88)")
J1_JUMP = ("an unpredictable jump in velocity can frequently occur when the transmission "
           "harnesses just enough energy to push through a system resonance (§2.6 p. 86)")
MODEL4 = ("model 4 (no resonance dissipation): the velocity jump that occurs in experimental "
          "response when resonance vibrations cease does not appear (§3 p. 137)")
TORQUE_ZERO = ("the measured torque response in all cases oscillated around zero at all "
               "velocities (§2.6 p. 91)")
TORQUE_80 = ("on ... joint 1, torque readings reached a powerful 80 N-m during system "
             "resonance (§2.6 p. 91)")
J2_TEXT = ("on joint 2 ... regions of resonant behavior can still be found at about 10000 "
           f"degrees/second and, to a lesser extent, 20000 degrees/second ({P87})")
SAME_SPEED = ("identical behavior can be observed around the resonance regimes on joints 2 "
              "and 3 (§2.6 p. 88): several currents, the same final velocity")
J3_TEXT = ("on joint 3, three resonant areas can be observed at the approximate input "
           f"velocities of 5000, 10000, and 20000 degrees/second ({P87})")
TOP_STEP = ("the input velocity of the three harmonic drives passes through regions where "
            f"significant resonance vibration can occur ({P87}; issue 12: beyond 15,000 °/s "
            "at the top step)")


def _deg(runs: StepRuns) -> np.ndarray:
    return np.degrees(runs.speed)


def plateau_at(cur: np.ndarray, sp: np.ndarray, target: float, min_len: int = 3
               ) -> tuple[int, int] | None:
    """T4/T5's plateau: ``min_len`` or more consecutive currents whose speeds ``sp`` (°/s)
    lie within 10 % of each other, their mean within :data:`SPEED_TOL` of ``target``."""
    return plateau_near(cur, sp, target, SPEED_TOL, 0.10, min_len)


def area_at(ru: RunUp, target: float) -> tuple[float, float, bool]:
    """T4/T5's resonant area near ``target`` (°/s) on the run-up curve: its height over
    the flanks, the speed it stands at, and whether it stands :data:`PROMINENCE` high."""
    height, at = ru.prominence(target, SPEED_TOL)
    return height, at, bool(np.isfinite(height) and height >= PROMINENCE)


def _plateau_check(item: Item, joint: str, cur: np.ndarray, sp: np.ndarray, target: float,
                   passage: str, min_len: int = 3) -> bool:
    """A plateau of ``min_len`` or more consecutive currents within 10 % near ``target``."""
    pl = plateau_at(cur, sp, target, min_len)
    model = ("none" if pl is None else f"{cur[pl[0]]:g}-{cur[pl[1]]:g} A at "
             f"{np.mean(sp[pl[0]: pl[1] + 1]):,.0f} °/s")
    return item.check(f"{joint}: plateau near {target:,.0f} °/s", passage,
                      f"{target:,.0f} °/s", f"≥ {min_len} consecutive currents within 10 % of "
                      f"each other, mean ±{100 * SPEED_TOL:.0f} %", model, pl is not None)


def _area_check(item: Item, joint: str, ru: RunUp, target: float, passage: str) -> bool:
    """A resonant area near ``target`` on the run-up curve ``ru``."""
    height, at, ok = area_at(ru, target)
    model = ("no data in the window" if not np.isfinite(height) else
             f"torque fluctuation peak x{height:.2f} at {at:,.0f} °/s")
    return item.check(f"{joint}: resonant area near {target:,.0f} °/s", passage,
                      f"{target:,.0f} °/s", f"a run-up peak ≥ x{PROMINENCE} over its flanks, "
                      f"within ±{100 * SPEED_TOL:.0f} %", model, ok)


def _speed_figure(runs: StepRuns, ru: RunUp, cur: np.ndarray, name: str,
                  marks: tuple[float, ...], path: Path, item: Item, ok: bool,
                  label: str = "A") -> Item:
    """Tuttle's axes (input velocity against time, figs D.x.2) beside the speed-current
    table and the run-up curve."""
    plt = plt_module()
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.5))
    t = np.arange(runs.wg_speed.shape[0]) * runs.ctrl_dt
    for k in range(cur.size):
        axes[0].plot(t, np.degrees(runs.wg_speed[:, k]), lw=0.4)
    axes[0].set_xlabel("time (s)")
    axes[0].set_ylabel("input velocity (°/s)")
    axes[0].set_title(f"{name}: current steps (Tuttle's axes, fig D.x.2)")
    sp = _deg(runs)
    axes[1].plot(cur, sp, "o-")
    for m in marks:
        axes[1].axhspan(m * (1 - SPEED_TOL), m * (1 + SPEED_TOL), color="orange", alpha=0.15)
    axes[1].set_xlabel(f"step current ({label})")
    axes[1].set_ylabel("mean input velocity, last 2 s (°/s)")
    axes[1].set_title("speed against current (bands: the paper's resonance speeds ±15 %)")
    axes[2].semilogx(ru.speed, ru.level, ".-")
    for m in marks:
        axes[2].axvspan(m * (1 - SPEED_TOL), m * (1 + SPEED_TOL), color="orange", alpha=0.15)
    axes[2].set_xlabel("input velocity (°/s)")
    axes[2].set_ylabel("torque fluctuation, median of 50 ms windows (N m)")
    axes[2].set_title("run-up over all steps")
    return finish(item, fig, path, ok)


@dataclass
class Joint1Steps:
    """T2's measurements on a joint: the current steps with all effects (model 5) and with
    load_dependent_friction off (model 4), and the item's criteria on them."""

    cur: np.ndarray  # step currents, A
    runs: StepRuns  # models 5 then 4, one column per current each
    m5: np.ndarray  # mean speed per current, model 5, °/s
    m4: np.ndarray  # likewise, model 4
    res: PlateauResult  # model 5's plateau in 2.8-4.0 A and its jump
    res4: PlateauResult  # model 4's
    smooth4: bool  # model 4 grows smoothly from below 2.8 A through model 5's breakout
    rise4: float  # model 4's largest relative rise over that range

    @property
    def plateau_mean(self) -> float:
        """Mean speed over model 5's plateau, °/s (nan without one)."""
        if self.res.plateau is None:
            return float("nan")
        a, b = self.res.plateau
        return float(np.mean(self.m5[a: b + 1]))

    @property
    def speed_ok(self) -> bool:
        return within(self.plateau_mean, PLATEAU_SPEED_DEG, SPEED_TOL)

    @property
    def model4_ok(self) -> bool:
        return self.res4.plateau is None and self.smooth4

    @property
    def passed(self) -> bool:
        return (self.res.plateau is not None and self.speed_ok and self.res.jump is not None
                and self.model4_ok)


def joint1_steps(p: JointParams) -> Joint1Steps:
    """Run T2's current steps on joint ``p`` (models 5 and 4) and judge them."""
    cur = np.array(STEP_CURRENTS)
    n = cur.size
    runs = step_runs([p] * n + [p.without("load_dependent_friction")] * n,
                     np.concatenate([cur, cur]))
    m5, m4 = np.degrees(runs.speed[:n]), np.degrees(runs.speed[n:])
    res = plateau_jump(cur, m5, window=(2.8, 4.0), min_len=4)
    res4 = plateau_jump(cur, m4)
    hi = (res.jump + 2) if res.jump is not None else n
    lo = int(np.searchsorted(cur, 2.8 - 1e-9))
    smooth4, rise4 = grows_smoothly(m4[max(lo - 1, 0): hi])
    return Joint1Steps(cur, runs, m5, m4, res, res4, smooth4, rise4)


def check_joint1_steps(out: Path, quick: bool) -> Item:
    """(T2) Joint 1: velocity plateau and jump in the 2x resonance, none without tooth friction."""
    item = Item("T2", "Joint 1: velocity plateau and jump in the 2x resonance (Tuttle §2.6)",
                "4 s current steps from rest, 1.6-6.0 A by 0.4 A, mean input speed over the "
                "last 2 s: the currents 2.8-4.0 A within 10 % of each other, their mean within "
                "±15 % of 8,000 °/s, then a rise of at least 30 % between two consecutive "
                "currents; with load_dependent_friction off (model 4): no plateau in 2.8-4.0 A "
                "and the speed grows smoothly from 2.4 A through the breakout current (rises "
                "at every step; no step rises by 30 % or more and by more than twice the "
                "median rise)",
                role="tuned on: tuttle-joint1 motor.torque_constant and compliance.damping "
                     "(see the preset's [sources]); so this item is not an independent check "
                     "of those two numbers")
    st = joint1_steps(preset("tuttle-joint1"))
    cur, runs, m5, m4, res, res4, rise4 = st.cur, st.runs, st.m5, st.m4, st.res, st.res4, st.rise4
    n = cur.size
    pl = "none"
    if res.plateau is not None:
        a, b = res.plateau
        pl = f"{cur[a]:g}-{cur[b]:g} A, spread {100 * res.spread:.1f} %"
    item.check("joint 1: plateau currents", J1_PLATEAU, "2.8-4.0 A",
               "all of 2.8-4.0 A within 10 % of each other", pl, res.plateau is not None)
    item.check("joint 1: plateau speed", J1_SPEEDS, "8,000 °/s", "±15 %",
               f"{st.plateau_mean:,.0f} °/s", st.speed_ok)
    item.check("joint 1: jump out of the plateau", J1_JUMP, "a jump",
               "≥ +30 % between consecutive currents",
               "none" if res.jump is None else
               f"{cur[res.jump]:g} -> {cur[res.jump + 1]:g} A: +{100 * res.jump_ratio:.0f} %",
               res.jump is not None)
    item.check("joint 1, model 4 (no tooth friction): no plateau, no jump", MODEL4,
               "no jump", "no plateau in 2.8-4.0 A; smooth from 2.4 A through the breakout",
               f"{'no plateau' if res4.plateau is None else 'plateau'}, largest rise "
               f"+{100 * rise4:.0f} % ({'smooth' if st.smooth4 else 'not smooth'})",
               st.model4_ok)
    item.passed = all(c.passed for c in item.checks)
    item.measured.append("currents (A): " + " | ".join(f"{c:.1f}" for c in cur))
    item.measured.append("model 5 (all effects), mean speed (°/s): "
                         + " | ".join(f"{v:.0f}" for v in m5))
    item.measured.append("model 4 (load_dependent_friction off), mean speed (°/s): "
                         + " | ".join(f"{v:.0f}" for v in m4))
    plt = plt_module()
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5))
    ax = axes[0]
    ax.plot(cur, m5, "o-", label="model 5: all effects (tooth friction μ' |T_k| on)")
    ax.plot(cur, m4, "s--", label="model 4: load_dependent_friction off")
    if res.plateau is not None:
        a, b = res.plateau
        ax.axvspan(cur[a] - 0.05, cur[b] + 0.05, color="orange", alpha=0.2, label="plateau")
    ax.axhline(PLATEAU_SPEED_DEG, color="grey", lw=0.8, ls=":", label="2x resonance ≈ 8,000 °/s")
    ax.set_xlabel("step current (A)")
    ax.set_ylabel("mean input speed, last 2 s (°/s)")
    ax.set_title("tuttle-joint1: current steps from rest")
    ax.legend(fontsize=8)
    ax = axes[1]
    t = np.arange(runs.wg_speed.shape[0]) * runs.ctrl_dt
    for k in range(n):
        ax.plot(t, np.degrees(runs.wg_speed[:, k]), lw=0.4, label=f"{cur[k]:.1f} A")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("input velocity (°/s)")
    ax.set_title("model 5 steps (Tuttle's axes, fig D.1.2)")
    ax.legend(fontsize=6, ncol=2)
    return finish(item, fig, out / "joint1_steps.png", item.passed)


def _joint1_plateau(p: JointParams) -> tuple[StepRuns, tuple[int, int] | None]:
    cur = np.array(STEP_CURRENTS)
    runs = step_runs(p, cur)
    res = plateau_jump(cur, _deg(runs))
    return runs, res.plateau


def check_joint1_torque(out: Path, quick: bool) -> Item:
    """(T3) Joint 1 torque sensor at the 2x plateau: around zero, peaks near 80 N m."""
    item = Item("T3", "Joint 1 torque sensor at the 2x plateau (Tuttle §2.6 p. 91, §3 p. 113)",
                "the steps of T2; over the last 2 s of each plateau current: the mean "
                "flexspline torque within ±10 N m of zero at every plateau current, and the "
                "largest |torque| over the plateau currents in 60-110 N m; for information, "
                "the same with the transmission friction placed between output and ground "
                "(friction.placement = output)",
                role="held-out check: no number was tuned on it (K_t and damping were "
                     "calibrated on T2 alone, after the tooth coefficient took the flank's "
                     "sliding, mu' = mu/(sin alpha cos alpha) from Tuttle eq. 3.81: "
                     "docs/physics.md eq. 7)")
    p = preset("tuttle-joint1")
    cur = np.array(STEP_CURRENTS)
    runs, pl = _joint1_plateau(p)
    alt = p.set("friction.placement", "output")
    runs_alt, pl_alt = _joint1_plateau(alt)
    if pl is None:
        item.check("joint 1: torque mean at the plateau", TORQUE_ZERO, "0 N m", "±10 N m",
                   "no plateau", False)
        item.check("joint 1: torque peak at the plateau", TORQUE_80, "80 N m", "60-110 N m",
                   "no plateau", False)
        item.passed = False
        return item
    a, b = pl
    means = runs.torque_mean[a: b + 1]
    peaks = runs.torque_peak[a: b + 1]
    worst = float(means[np.argmax(np.abs(means))])
    item.check("joint 1: torque mean at the plateau", TORQUE_ZERO, "0 N m", "±10 N m",
               f"{worst:+.1f} N m (largest of {cur[a]:g}-{cur[b]:g} A)", torque_mean_ok(worst))
    top = float(peaks.max())
    item.check("joint 1: torque peak at the plateau", TORQUE_80, "80 N m",
               f"{TORQUE_PEAK_BAND[0]:.0f}-{TORQUE_PEAK_BAND[1]:.0f} N m",
               f"{top:.0f} N m (at {cur[a + int(np.argmax(peaks))]:g} A)", torque_peak_ok(top))
    item.passed = all(c.passed for c in item.checks)
    item.measured.append(
        "friction in the mesh (the preset): per plateau current " + "; ".join(
            f"{cur[k]:g} A: mean {runs.torque_mean[k]:+.1f}, peak {runs.torque_peak[k]:.0f} N m"
            for k in range(a, b + 1)))
    if pl_alt is not None:
        a2, b2 = pl_alt
        item.measured.append(
            "for information, friction between output and ground (placement = output): "
            + "; ".join(f"{cur[k]:g} A: mean {runs_alt.torque_mean[k]:+.1f}, peak "
                        f"{runs_alt.torque_peak[k]:.0f} N m" for k in range(a2, b2 + 1)))
    else:
        item.measured.append("for information, placement = output: no plateau")
    item.measured.append(
        "for information, the same run (placement = output) read as Tuttle's models 4 and 5 "
        "would: friction between the splines on the output side of the compliance, the "
        "sensor on the grounded spline reading the output's inertial torque J_o dω_o/dt; "
        "its peak at " + ", ".join(f"{cur[k]:g}" for k in range(a, b + 1)) + " A: "
        + " / ".join(f"{runs_alt.inertial_peak[k]:.0f}" for k in range(a, b + 1))
        + " N m (the preset's currents; K_t and damping were calibrated for the mesh "
        "placement, and with it the joint-1 speeds no longer form T2's plateau)")
    plt = plt_module()
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.5), sharey=True)
    t = np.arange(runs.torque.shape[0]) * runs.ctrl_dt
    for ax, r, title in ((axes[0], runs, "friction in the mesh (preset)"),
                         (axes[1], runs_alt, "friction output-to-ground")):
        for k in range(a, b + 1):
            ax.plot(t, r.torque[:, k], lw=0.3, label=f"{cur[k]:g} A")
        ax.axhline(0.0, color="k", lw=0.6)
        for v in (80.0, -80.0):
            ax.axhline(v, color="grey", lw=0.8, ls=":")
        ax.set_xlabel("time (s)")
        ax.set_title(f"tuttle-joint1 torque sensor: {title}", fontsize=10)
        ax.legend(fontsize=7)
    axes[0].set_ylabel("flexspline torque (N m) (Tuttle's axes, fig D.1.7; ±80 N m dotted)")
    return finish(item, fig, out / "joint1_torque.png", item.passed)


def check_joint2_steps(out: Path, quick: bool) -> Item:
    """(T4) Joint 2: resonant plateau near 10,000 °/s, a lesser resonant area near 20,000."""
    item = Item("T4", "Joint 2: resonant regions near 10,000 and 20,000 °/s (Tuttle §2.6)",
                "4 s current steps from rest, 1.4-4.4 A by 0.2 A and 4.5 A: a plateau near "
                "10,000 °/s (≥ 3 consecutive currents within 10 % of each other, mean ±15 %), "
                "and a resonant area near 20,000 °/s: on the run-up curve (torque "
                "fluctuation in 50 ms windows against speed, pooled over the steps) a peak "
                "within ±15 % standing ≥ 1.3x above the higher of its flanking minima",
                role="tuned on (plateau near 10,000 °/s): tuttle-joint2 compliance.cubic and "
                     "hysteresis.element_strength; the 20,000 °/s area is a check")
    p = preset("tuttle-joint2")
    cur = np.array(CURRENTS_2)
    runs = step_runs(p, cur)
    sp, ru = _deg(runs), run_up(runs)
    ok = _plateau_check(item, "joint 2", cur, sp, 10000.0, J2_TEXT + "; " + SAME_SPEED)
    ok &= _area_check(item, "joint 2", ru, 20000.0, J2_TEXT)
    item.passed = bool(ok)
    item.measured.append("currents (A): " + " | ".join(f"{c:g}" for c in cur))
    item.measured.append("mean speed (°/s): " + " | ".join(f"{v:.0f}" for v in sp))
    return _speed_figure(runs, ru, cur, "tuttle-joint2", (10000.0, 20000.0),
                         out / "joint2_steps.png", item, item.passed)


def check_joint3_steps(out: Path, quick: bool) -> Item:
    """(T5) Joint 3: resonant areas near 5,000, 10,000 and 20,000 °/s, run through."""
    item = Item("T5", "Joint 3: three resonant areas, run through (Tuttle §2.6)",
                "4 s current steps from rest, 0.28-0.60 A by 0.02 A: resonant areas near "
                "5,000 and 20,000 °/s on the run-up curve (a peak within ±15 % ≥ 1.3x above "
                "its flanks), a plateau near 10,000 °/s (≥ 3 consecutive currents within 10 %, "
                "mean ±15 %), and the top step's mean speed beyond 15,000 °/s",
                role="tuned on: tuttle-joint3 motor.torque_constant, compliance.damping and "
                     "the kinematic-error split (see the preset's [sources]); the peak-to-peak "
                     "kinematic error (T1) and the small-signal resonance (T6) check them")
    p = preset("tuttle-joint3")
    cur = np.array(CURRENTS_3)
    runs = step_runs(p, cur)
    sp, ru = _deg(runs), run_up(runs)
    ok = _area_check(item, "joint 3", ru, 5000.0, J3_TEXT)
    ok &= _plateau_check(item, "joint 3", cur, sp, 10000.0, J3_TEXT + "; " + SAME_SPEED)
    ok &= _area_check(item, "joint 3", ru, 20000.0, J3_TEXT)
    ok &= item.check("joint 3: top step runs through", TOP_STEP, "> 15,000 °/s at 0.60 A",
                     "mean speed > 15,000 °/s", f"{sp[-1]:,.0f} °/s", bool(sp[-1] > 15000.0))
    item.passed = bool(ok)
    item.measured.append("currents (A): " + " | ".join(f"{c:g}" for c in cur))
    item.measured.append("mean speed (°/s): " + " | ".join(f"{v:.0f}" for v in sp))
    return _speed_figure(runs, ru, cur, "tuttle-joint3", (5000.0, 10000.0, 20000.0),
                         out / "joint3_steps.png", item, item.passed)
