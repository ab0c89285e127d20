"""Write ``results/rl/``: evaluation table, learning curve, speed-against-time figure.

    python -m agents.train --config resonance_ppo --out runs/resonance_ppo-s0
    cp runs/resonance_ppo-s0/final.zip agents/policies/resonance_ppo.zip
    python -m agents.report --run runs/resonance_ppo-s0

Two parts: the default task (the preset's 6 A amplifier: the committed
policy against the PI speed loop and constant full current) and the
trap-only variant ``current_limit=3.7`` (full current, the PI, the
shaped-current baselines and ``--trap-policy``, the PPO policy trained on
that variant in commit 850dd0c), with the physical reason why nothing
crosses there.

``--run`` is a training output directory (monitor files, ``eval/``,
``train.json``); without it (or if it is missing) the learning curve is
redrawn from ``results/rl/learning_curve.csv`` when that exists.
"""

from __future__ import annotations

import argparse
import copy
import csv
import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from agents.baselines import PISpeedController
from agents.common import load_policy, policy_config
from agents.evaluate import (
    TRAP_SPEED,
    episode_metrics,
    evaluate,
    label,
    make_batch_env,
    markdown_table,
    smoothed,
)
from hdgym.envs.common import resolve_params
from hdgym.envs.resonance import TRAP_ONLY_CURRENT_LIMIT

DEFAULT_POLICY = Path(__file__).parent / "policies" / "resonance_ppo.zip"
#: the PPO policy trained on the 3.7 A trap-only variant (commit 850dd0c, same config otherwise)
TRAP_POLICY = Path(__file__).parent / "policies" / "resonance_ppo_trap37.zip"
#: what 850dd0c measured for that policy on the same 100 episodes (when the zip is missing)
TRAP_POLICY_850DD0C = {"reached": 0.07, "trapped": 0.93, "peak": (145, 165)}
CONTROLLERS = ["policy", "pi", "full"]
#: constant-current steps (Tuttle §2.6 used 1.6-6.0 A) with the preset's own amplifier:
#: where the trap holds, and where the task's current limit sits among them
STEPS = ["const@2.8A", "const@3.4A", "const@3.6A", "const@3.7A", "const@3.8A", "const@4.0A",
         "const@4.5A", "const@5.0A", "full", "pi"]
#: full current shaped against the vibration (run with an action repeat of 1: 1 ms)
SHAPED = [f"ripple@0.1,{d}" for d in (0, 90, 180, 270)] + \
    [f"damp@0.15,{d}" for d in (0, 90, 180, 270)]
#: the issue's requirements
TRAP_GOAL = 0.9
REACH_GOAL = 0.9


def preset_amplifier_config(cfg: dict[str, Any]) -> dict[str, Any]:
    """The same env config with the preset's own amplifier (``current_limit`` None)."""
    out = copy.deepcopy(cfg)
    out["env"].setdefault("kwargs", {})["current_limit"] = None
    return out


def trap_only_config(cfg: dict[str, Any],
                     limit: float = TRAP_ONLY_CURRENT_LIMIT) -> dict[str, Any]:
    """The same env config with the trap-only variant's amplifier (``current_limit`` 3.7 A)."""
    out = copy.deepcopy(cfg)
    out["env"].setdefault("kwargs", {})["current_limit"] = limit
    return out


def every_period_config(cfg: dict[str, Any]) -> dict[str, Any]:
    """The same env config with a new action every control period."""
    out = copy.deepcopy(cfg)
    out["env"]["action_repeat"] = 1
    return out


def relabel_preset_steps(stats: list[Any], amps: float) -> None:
    """Name the reference rows after the preset's amplifier (they are not the task's)."""
    for s in stats:
        if s.controller == "full":
            s.controller = f"constant {amps:g} A (the preset's full current)"
        elif s.controller == "pi":
            s.controller = f"PI speed loop, the preset's {amps:g} A amplifier"


def read_monitors(run: Path) -> tuple[np.ndarray, np.ndarray]:
    """(cumulative agent steps, episode return) over all training envs, in time order."""
    rows = []
    for f in sorted((run / "monitor").glob("*.monitor.csv")):
        with f.open() as fh:
            fh.readline()  # '#{"t_start": ...}'
            for r in csv.DictReader(fh):
                rows.append((float(r["t"]), float(r["r"]), int(r["l"])))
    rows.sort()
    if not rows:
        return np.zeros(0), np.zeros(0)
    t, r, n = (np.array(c) for c in zip(*rows, strict=True))
    return np.cumsum(n), r


def learning_curve(run: Path | None, out: Path, repeat: int = 5) -> dict[str, Any]:
    """Write learning_curve.csv (when ``run`` has logs) and learning_curve.png."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    csv_path = out / "learning_curve.csv"
    info: dict[str, Any] = {}
    if run is not None and (run / "monitor").is_dir():
        steps, ret = read_monitors(run)
        ev = run / "eval" / "evaluations.npz"
        es, er = (np.zeros(0), np.zeros((0, 1)))
        if ev.exists():
            d = np.load(ev)
            es, er = d["timesteps"], d["results"]
        with csv_path.open("w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["source", "agent_steps", "episode_return"])
            for s, r in zip(steps, ret, strict=True):
                w.writerow(["train", int(s), f"{r:.3f}"])
            for s, r in zip(es, er.mean(axis=1), strict=True):
                w.writerow(["eval_mean", int(s), f"{r:.3f}"])
        if (run / "train.json").exists():
            info = json.loads((run / "train.json").read_text())
    if not csv_path.exists():
        return info
    train_s, train_r, ev_s, ev_r = [], [], [], []
    with csv_path.open() as fh:
        for row in csv.DictReader(fh):
            (train_s if row["source"] == "train" else ev_s).append(int(row["agent_steps"]))
            (train_r if row["source"] == "train" else ev_r).append(float(row["episode_return"]))
    fig, ax = plt.subplots(figsize=(7, 4))
    if train_s:
        ts, tr = np.array(train_s), np.array(train_r)
        ax.plot(ts, tr, ".", ms=2, alpha=0.3, color="C0", label="training episodes")
        k = min(32, len(tr))
        ax.plot(ts[k - 1:], np.convolve(tr, np.ones(k) / k, "valid"), color="C0",
                label=f"training, mean of {k}")
    if ev_s:
        ax.plot(ev_s, ev_r, "o-", color="C3", label="evaluation (deterministic)")
    ax.set_xlabel(f"agent steps (one step = {repeat} control periods of 1 ms)")
    ax.set_ylabel("episode return\n(env reward + torque shaping, per agent step)")
    ax.set_title("PPO on HarmonicDriveResonance-v0 (tuttle-joint1, randomized)")
    ax.grid(alpha=0.3)
    ax.legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(out / "learning_curve.png", dpi=110)
    plt.close(fig)
    return info


def speed_figure(traces: dict[str, dict[str, np.ndarray]], out: Path, episode: int = 0,
                 filename: str = "speed_vs_time.png", title: str = "",
                 labels: dict[str, str] | None = None) -> None:
    """Speed against time, one episode per controller, with flexspline torque and current."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, axt, axi) = plt.subplots(3, 1, figsize=(8, 8.5), sharex=True,
                                       gridspec_kw={"height_ratios": [3, 2, 1.5]})
    colors = {"policy": "C2", "pi": "C1", "full": "C0", "trap_policy": "C3"}
    styles = {"pi": "--", "trap_policy": ":"}
    tgt = None
    for name, tr in traces.items():
        t = tr["time"]
        dt = float(t[1] - t[0])
        n = int(tr["length"][episode])
        w = np.degrees(smoothed(tr["speed"][episode : episode + 1, :n], dt)[0])
        c = colors.get(name)
        ax.plot(t[:n], np.degrees(tr["speed"][episode, :n]), color=c, lw=0.4, alpha=0.35)
        ax.plot(t[:n], w, color=c, lw=1.6, ls=styles.get(name, "-"),
                label=(labels or {}).get(name, label(name)))
        axt.plot(t[:n], tr["torque"][episode, :n], color=c, lw=0.5, alpha=0.8)
        axi.plot(t[:n], tr["current"][episode, :n], color=c, lw=0.6, ls=styles.get(name, "-"))
        tgt = math.degrees(float(tr["target"][episode]))
    if tgt is not None:
        ax.axhline(tgt, color="k", ls="--", lw=1, label=f"target {tgt:,.0f} deg/s")
    ax.axhspan(7000, 8600, color="0.85", zorder=0, label="2x-order resonance trap")
    ax.axhline(math.degrees(TRAP_SPEED), color="0.5", ls=":", lw=1)
    ax.set_ylabel("motor speed (deg/s)\nthin: true, thick: 50 ms mean")
    ax.set_ylim(0, max(1.6 * (tgt or 10000), 14000))
    ax.legend(loc="upper left", fontsize=8)
    ax.grid(alpha=0.3)
    ax.set_title(title or "Same randomized episode (env seed) for every controller")
    axt.set_ylabel("flexspline torque (N m)")
    axt.grid(alpha=0.3)
    axi.set_ylabel("motor current (A)")
    axi.set_xlabel("time (s)")
    axi.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / filename, dpi=90)
    plt.close(fig)


def pct(x: float) -> str:
    return f"{100 * x:.0f} %"


def trap_phase_current(tr: dict[str, np.ndarray]) -> tuple[float, float, float]:
    """Mean, 1st and 99th percentile of the motor current (A) before the 50 ms mean speed
    first exceeds 9,000 deg/s (the whole episode if it never does)."""
    dt = float(tr["time"][1] - tr["time"][0])
    ws = smoothed(tr["speed"], dt)
    above = ws >= TRAP_SPEED
    first = np.where(above.any(axis=1), np.argmax(above, axis=1), tr["length"])
    mask = np.arange(ws.shape[1])[None, :] < first[:, None]
    cur = tr["current"][mask]
    return float(cur.mean()), float(np.percentile(cur, 1)), float(np.percentile(cur, 99))


def default_findings(stats: dict[str, Any], mean_current: dict[str, float],
                     check: Any = None, check_seed: int = 0,
                     trap_current: dict[str, tuple[float, float, float]] | None = None,
                     steps: dict[str, Any] | None = None) -> str:
    """Sentences on table 1 (the default 6 A task), regenerated with the numbers."""
    pol, pi, full = (stats[k] for k in ("policy", "pi", "full"))
    ratio = pol.peak_torque_mean / full.peak_torque_mean
    lines = [
        f"- The PPO policy reaches the target in {pct(pol.reached)} of the episodes (trapped "
        f"{pct(pol.trapped)}), in {pol.time_to_target_s:.2f} s on average, with a peak "
        f"flexspline torque of {pol.peak_torque_mean:.0f} N m mean (max "
        f"{pol.peak_torque_max:.0f}): {100 * ratio:.0f} % of constant full current's "
        f"{full.peak_torque_mean:.0f} N m (max {full.peak_torque_max:.0f}), which gets there "
        f"in {full.time_to_target_s:.2f} s, and "
        f"{100 * pol.peak_torque_mean / pi.peak_torque_mean:.0f} % of the PI speed loop's "
        f"{pi.peak_torque_mean:.0f} N m (reached {pct(pi.reached)}, "
        f"{pi.time_to_target_s:.2f} s). The policy trades about "
        f"{pol.time_to_target_s - full.time_to_target_s:.1f} s of run-up for "
        f"{full.peak_torque_mean - pol.peak_torque_mean:.0f} N m less peak torque.",
        f"- Mean motor current over the episodes: policy {mean_current['policy']:.2f} A, PI "
        f"{mean_current['pi']:.2f} A, constant full current {mean_current['full']:.2f} A.",
        f"- With the preset's amplifier brute force crosses too (full current reaches the "
        f"target in {pct(full.reached)}, the PI in {pct(pi.reached)}), so this task is about "
        "the torque on the way through the trap, not about whether the trap can be crossed.",
    ]
    if trap_current and steps:
        mc, lo, hi = trap_current["policy"]
        near = min((k for k in steps if k.startswith("const@") and k.endswith("A")),
                   key=lambda k: abs(float(k[6:-1]) - mc))
        lines.append(
            f"- How the policy gets through: below 9,000 deg/s its current averages {mc:.2f} A "
            f"but swings between {lo:.1f} and {hi:.1f} A (1st/99th percentile; full current "
            f"{trap_current['full'][0]:.2f} A): it modulates the current with the torsional "
            f"oscillation over most of the amplifier's range (`speed_vs_time.png`). "
            f"A constant {near[6:-1]} A reaches the target in "
            f"only {pct(steps[near].reached)} of the same episodes (table 3), so here the "
            "shaping, not the mean current alone, carries it through. It needs headroom above "
            "its mean: with a 3.7 A limit every swing lowers the mean current below 3.7 A "
            "(part 2).")
    if check is not None:
        lines.append(
            f"- On {check.episodes} other episodes (seeds {check_seed}-"
            f"{check_seed + check.episodes - 1}) the committed policy reaches the target in "
            f"{pct(check.reached)} (trapped {pct(check.trapped)}), peak torque "
            f"{check.peak_torque_mean:.0f} / {check.peak_torque_max:.0f} N m, time to target "
            f"{check.time_to_target_s:.2f} s.")
    return "\n".join(lines) + "\n"


def physics_numbers(params: Any) -> dict[str, float]:
    """Reflected inertia, the spring torque a full-current swing moves, the KE forcing."""
    m, c, n = params.motor, params.compliance, params.ratio
    j_ref, j_out = m.inertia * n ** 2, params.load.inertia
    t_motor = m.torque_constant * TRAP_ONLY_CURRENT_LIMIT * n
    t_motor6 = m.torque_constant * params.amplifier.current_limit * n
    share = j_out / (j_ref + j_out)
    ke2 = [h.amplitude for h in params.kinematic_error.harmonics if h.order == 2.0]
    return {"j_ref": j_ref, "j_out": j_out, "ratio": n, "share": share,
            "mode_37": share * t_motor, "mode_6": share * t_motor6,
            "ke_lo": c.stiffness * max(ke2), "ke_hi": c.stiffness * sum(ke2)}


def trap_findings(tstats: dict[str, Any], shaped: list[Any], params: Any, preset_amps: float,
                  trap_policy: Any) -> str:
    """Sentences on table 2 (the 3.7 A trap-only variant) and issue 6's requirement."""
    full, pi = tstats["full"], tstats["pi"]
    m, a = params.motor, params.amplifier
    i_bemf = (a.voltage_limit - m.back_emf_constant * math.radians(8000.0)) / m.resistance
    best = max(shaped, key=lambda s: (s.reached, s.max_speed_deg_s))
    if trap_policy is not None:
        pol_reach, pol_trap = trap_policy.reached, trap_policy.trapped
        pol_src = "the PPO policy trained on this variant"
    else:
        pol_reach, pol_trap = (TRAP_POLICY_850DD0C[k] for k in ("reached", "trapped"))
        pol_src = "the PPO policy trained on this variant (measured in commit 850dd0c)"
    crossers = [s.reached for s in shaped] + [pol_reach]
    lines = [
        f"- The amplifier is limited to {TRAP_ONLY_CURRENT_LIMIT:g} A (the preset's is "
        f"{preset_amps:g} A); the back-EMF limit (V - K_b w)/R is still {i_bemf:.1f} A at "
        "8,000 deg/s, so the current limit is what binds in the trap. Constant full current "
        f"is trapped in {pct(full.trapped)} of the episodes, the PI speed loop (at the limit "
        f"through the run-up) in {pct(pi.trapped)}.",
        f"- Nothing crosses: {pol_src} reaches the target in {pct(pol_reach)} (trapped "
        f"{pct(pol_trap)}; it learned to command full current), the best shaped current, "
        f"{label(best.controller)}, in {pct(best.reached)} (highest speed "
        f"{best.max_speed_deg_s:,.0f} deg/s, against {full.max_speed_deg_s:,.0f} deg/s for "
        "full current): the ripple or damping costs mean current, which the trap's speed "
        "follows, faster than it saves friction.",
        "- **Issue 6's requirement \"PI trapped >= 90 % while the policy crosses >= 90 %\" is "
        f"{'' if pi.trapped >= 0.9 and pol_reach >= 0.9 else 'not '}met in this model**: the PI "
        f"is trapped in {pct(pi.trapped)} (that half "
        f"{'holds' if pi.trapped >= 0.9 else 'does not hold'}), "
        f"but no controller tried crosses in more than {pct(max(crossers + [full.reached]))} "
        f"(the policy {pct(pol_reach)}, full current {pct(full.reached)}). With the preset's "
        "6 A amplifier (table 1) the policy crosses, but so does the PI.",
    ]
    return "\n".join(lines) + "\n"


def physics_paragraph(ph: dict[str, float], steps: dict[str, Any], policy_mean: float) -> str:
    above = ", ".join(f"{k[6:-1]} A {pct(steps[k].reached)}"
                      for k in ("const@3.8A", "const@4.5A", "const@5.0A") if k in steps)
    return (
        f"Why the current cannot break the trap at {TRAP_ONLY_CURRENT_LIMIT:g} A: the motor's "
        f"inertia reflected through the ratio {ph['ratio']:g} is {ph['j_ref']:.1f} kg m^2 "
        f"against {ph['j_out']:.1f} kg m^2 at the output, so a motor torque reaches the "
        f"torsional mode's spring only with the share J_out / (J_m N^2 + J_out) = "
        f"{ph['share']:.2f}: a current step of I_max moves the mode's spring torque by about "
        f"{ph['mode_37']:.1f} N m at {TRAP_ONLY_CURRENT_LIMIT:g} A "
        f"({ph['mode_6']:.1f} N m at 6 A), while the 2x-order kinematic error forces it with "
        f"K x KE amplitude = {ph['ke_lo']:.0f}-{ph['ke_hi']:.0f} N m (circular-spline term "
        "alone / both 2x terms in phase). Both are amplified alike at the resonance, so a "
        "current swing can only partly counter the forcing, and with the limit at 3.7 A every "
        "swing comes out of the mean current that carries the speed up the plateau (at 6 A "
        f"the policy swings around a mean of {policy_mean:.1f} A: part 1). At constant "
        f"current, what crosses is more current (table 3, reached: {above}), i.e. a bigger "
        "amplifier, which is the default task.\n")


def write_markdown(out: Path, table: str, trap_table: str, steps_table: str,
                   cfg: dict[str, Any], pi_text: str, train_info: dict[str, Any], n: int,
                   seed: int, policy: str, found: str, trap_found: str, physics: str,
                   preset_amps: float, trap_policy: str | None) -> None:
    e = cfg["env"]
    kw = e.get("kwargs", {})
    rnd = ", ".join(f"`{k}` ±{100 * v:.0f} %" for k, v in kw.get("randomize", {}).items())
    lo, hi = (math.degrees(v) for v in kw.get("target_speed", [0, 0]))
    tp = e.get("torque_penalty") or {}
    shaping = (f"Training-only reward shaping: `{tp.get('weight')} * max(0, |T_fs| / "
               f"{tp.get('threshold')} N m - 1)^2` per control period (`[env.torque_penalty]`)."
               if tp else "")
    tinfo = ""
    if train_info:
        tinfo = (f"Training: {train_info.get('algo', '').upper()}, "
                 f"{train_info.get('agent_steps', 0):,} agent steps "
                 f"({train_info.get('control_periods', 0):,} control periods) on "
                 f"{train_info.get('n_envs')} envs (SB3 DummyVecEnv), seed "
                 f"{train_info.get('seed')}, wall time "
                 f"**{train_info.get('wall_time_s', 0) / 60:.1f} min** "
                 f"({train_info.get('agent_steps_per_s', 0):,.0f} agent steps/s) on the shared "
                 "2-core machine, one torch thread.\n")
    trap_src = (f"`{trap_policy}` (the policy committed in 850dd0c, trained with the same "
                "config and `current_limit = 3.7`)" if trap_policy else
                "not re-evaluated here (its zip is missing); 850dd0c measured 7 % reached, "
                "93 % trapped, peak torque 145 / 165 N m on these 100 episodes")
    text = f"""# Resonance trap: RL policy against baselines

Regenerate (training: the wall time below; report: a few minutes):

    python -m agents.train --config resonance_ppo --out runs/resonance_ppo-s0
    cp runs/resonance_ppo-s0/final.zip agents/policies/resonance_ppo.zip
    python -m agents.report --run runs/resonance_ppo-s0
    # second seed row: python -m agents.train --config resonance_ppo --seed 1 \\
    #   --out runs/resonance_ppo-s1, then add --also runs/resonance_ppo-s1 to the report

Evaluate the committed policy only:
`python -m agents.evaluate --policy {policy} --episodes {n} --seed {seed}
--controllers policy pi full`.

Two parts: **1.** the benchmark, `HarmonicDriveResonance-v0` as registered (the preset's
{preset_amps:g} A amplifier): reach the target speed through the trap while keeping the
flexspline torque oscillation low; **2.** the trap-only variant `current_limit=3.7`, where
brute force stays trapped and, as measured, no current shaping crosses either: issue 6's
premise does not hold in this model.

Env: preset tuttle-joint1, 40 V, back-EMF limit on;
{int(e['max_episode_steps'])} control periods of 1 ms per episode, the agent's action held for
{int(e['action_repeat'])} periods, target speed uniform in {lo:,.0f}-{hi:,.0f} deg/s,
randomized per episode: {rnd}. `oscillation_weight` {kw.get('oscillation_weight')},
`torque_limit` {kw.get('torque_limit')} N m (no episode is cut short, so the peak torque is
measured). {shaping}
{n} episodes, env `i` seeded `{seed} + i`: every controller sees the same drives, start
angles and targets, in both tables.

Metrics from the true states: *reached* = the 50 ms mean motor speed comes within 5 % of the
target; *trapped* = it never exceeds 9,000 deg/s; peak torque = largest |flexspline torque|
in the episode.

## 1. The default task: the preset's {preset_amps:g} A amplifier

{tinfo}
Table 1, the benchmark:

{table}
{found}
## 2. The trap-only variant: `current_limit=3.7`

The same episodes with the amplifier limited to 3.7 A (inside Tuttle's 2.8-4.0 A velocity
plateau); the action ±1 maps to ±3.7 A. The PPO row is {trap_src}. The shaped currents
(`agents/baselines.py`: `RippleCurrent`, a 2x-order ripple locked to the measured WG angle;
`DampingCurrent`, feedback from the torque sensor's oscillation, `phi` 90 deg = on its rate)
get a new command every control period (1 ms).

Table 2, the trap-only variant:

{trap_table}
{trap_found}
{physics}
Table 3, constant current steps on the same episodes with the preset's {preset_amps:g} A
amplifier (the trap near 8,000 deg/s, Tuttle §2.6): where 3.7 A sits, and what brute-force
current needs to break out:

{steps_table}
Baseline design: {pi_text}. Linear model `G(s) = K_t / (J s + b) / (s/w_a + 1)`, output
inertia reflected through the ratio, the spring left out (crossover far below the 44 Hz
torsional mode); gains from python-control; anti-windup by back-calculation onto
`min(I_max, (V - K_b w)/R)` (`agents/baselines.py`). The same gains in both tables; only
the limit differs.

Figures: `learning_curve.png` (training episode returns from the SB3 monitor files and the
periodic deterministic evaluation on 8 other seeds; data in `learning_curve.csv`),
`speed_vs_time.png` (the default task, episode 0: PI and full current against the policy;
speed, flexspline torque, current), `speed_vs_time_trap37.png` (the same episode at 3.7 A:
full current, PI and the 3.7 A policy, all trapped).
"""
    (out / "evaluation.md").write_text(text)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m agents.report", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--policy", type=Path, default=DEFAULT_POLICY)
    ap.add_argument("--trap-policy", type=Path, default=TRAP_POLICY,
                    help="policy trained on the 3.7 A trap-only variant (table 2)")
    ap.add_argument("--run", type=Path, help="training output directory (learning curve)")
    ap.add_argument("--also", type=Path, nargs="*", default=[],
                    help="more training runs whose final.zip to evaluate on the same episodes "
                    "(e.g. other seeds)")
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--out", type=Path, default=Path("runs/rl"),
                    help="folder to write (default %(default)s; committed: --out results/rl)")
    ap.add_argument("--check-seed", type=int, default=0,
                    help="first seed of a second, larger set of episodes for the policy only")
    ap.add_argument("--check-episodes", type=int, default=200)
    args = ap.parse_args(argv)
    if not args.policy.is_file():
        print(f"agents.report: no such policy {str(args.policy)!r}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    model = load_policy(args.policy)
    cfg = policy_config(args.policy)
    if cfg is None:
        print(f"agents.report: {args.policy} holds no agents config", file=sys.stderr)
        return 2
    if cfg["env"].get("kwargs", {}).get("current_limit") is not None:
        print("agents.report: --policy must be trained on the default task (no current_limit)",
              file=sys.stderr)
        return 2
    # 1. the default task
    stats, traces = evaluate(cfg, CONTROLLERS, args.episodes, args.seed, model)
    for run in args.also:
        other = load_policy(run / "final.zip")
        seed_stats, _ = evaluate(cfg, ["policy"], args.episodes, args.seed, other)
        tj = run / "train.json"
        tag = run.name
        if tj.exists():
            t = json.loads(tj.read_text())
            tag = f"{Path(t['config']).stem}, training seed {t['seed']}"
        seed_stats[0].controller = f"policy-{tag}"
        stats.append(seed_stats[0])
    check = None
    if args.check_episodes > 0:
        check = evaluate(cfg, ["policy"], args.check_episodes, args.check_seed, model)[0][0]
    # 2. the trap-only variant
    tcfg = trap_only_config(cfg)
    trap_stats, trap_traces = evaluate(tcfg, ["full", "pi"], args.episodes, args.seed)
    trap_pol = None
    trap_policy = None
    if args.trap_policy is not None and args.trap_policy.is_file():
        (trap_pol,), tr = evaluate(tcfg, ["policy"], args.episodes, args.seed,
                                   load_policy(args.trap_policy))
        trap_pol.controller = "policy-trained on current_limit=3.7, commit 850dd0c"
        trap_traces["trap_policy"] = tr["policy"]
        trap_stats.append(trap_pol)
        try:
            trap_policy = args.trap_policy.resolve().relative_to(Path.cwd()).as_posix()
        except ValueError:
            trap_policy = args.trap_policy.as_posix()
    shaped_stats, _ = evaluate(every_period_config(tcfg), SHAPED, args.episodes, args.seed)
    step_stats, _ = evaluate(preset_amplifier_config(cfg), STEPS, args.episodes, args.seed)
    probe = make_batch_env(cfg, 1, 0)
    u = probe.unwrapped
    preset = cfg["env"].get("kwargs", {}).get("preset")
    preset_amps = resolve_params(preset).amplifier.current_limit
    relabel_preset_steps(step_stats, preset_amps)
    table = markdown_table(stats)
    trap_table = markdown_table(trap_stats + shaped_stats)
    steps_table = markdown_table(step_stats)
    print(table)
    print(trap_table)
    print(steps_table)
    pi_text = PISpeedController(u.params, u.batch.speed_scale, u.batch.ctrl_dt).design.describe()
    info = learning_curve(args.run, args.out, int(cfg["env"]["action_repeat"]))
    if not info and (args.out / "train.json").exists():
        info = json.loads((args.out / "train.json").read_text())
    if info:
        (args.out / "train.json").write_text(json.dumps(info, indent=1) + "\n")
    speed_figure({k: traces[k] for k in ("pi", "full", "policy")}, args.out,
                 title=f"Default task ({preset_amps:g} A): same randomized episode for every "
                 "controller")
    speed_figure(trap_traces, args.out, filename="speed_vs_time_trap37.png",
                 title="Trap-only variant (current_limit=3.7): the same episode, all trapped\n"
                 "(the traces overlap: the policy commands full current, the PI saturates)",
                 labels={"trap_policy": "PPO policy trained at 3.7 A (850dd0c)"})
    per_ep = {name: {k: v.tolist() for k, v in episode_metrics(tr).items()}
              for name, tr in traces.items()}
    per_ep.update({f"trap37:{name}": {k: v.tolist() for k, v in episode_metrics(tr).items()}
                   for name, tr in trap_traces.items()})
    (args.out / "episodes.json").write_text(json.dumps(per_ep) + "\n")
    (args.out / "evaluation.json").write_text(json.dumps(
        {"default": [s.__dict__ for s in stats],
         "trap_only_3.7A": [s.__dict__ for s in trap_stats + shaped_stats],
         "preset_amplifier_steps": [s.__dict__ for s in step_stats],
         "check": None if check is None else check.__dict__}, indent=1) + "\n")
    try:
        policy = args.policy.resolve().relative_to(Path.cwd()).as_posix()
    except ValueError:
        policy = args.policy.as_posix()
    mean_current = {k: float(np.mean(traces[k]["current"])) for k in ("policy", "pi", "full")}
    trap_current = {k: trap_phase_current(traces[k]) for k in ("policy", "full")}
    found = default_findings({s.controller: s for s in stats}, mean_current, check,
                             args.check_seed, trap_current,
                             {s.controller: s for s in step_stats})
    trap_found = trap_findings({s.controller: s for s in trap_stats}, shaped_stats, u.params,
                               preset_amps, trap_pol)
    physics = physics_paragraph(physics_numbers(u.params),
                                {s.controller: s for s in step_stats}, trap_current["policy"][0])
    write_markdown(args.out, table, trap_table, steps_table, cfg, pi_text, info, args.episodes,
                   args.seed, policy, found, trap_found, physics, preset_amps, trap_policy)
    probe.close()
    print(f"wrote {args.out}/evaluation.md, learning_curve.png, speed_vs_time*.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
