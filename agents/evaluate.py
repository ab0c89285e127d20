"""Evaluate a saved policy and the baselines on randomized resonance episodes.

    python -m agents.evaluate --policy agents/policies/resonance_ppo.zip --episodes 50 --seed 1000
    python -m agents.evaluate --controllers pi full --episodes 20 --out results/rl/eval.md

All controllers run on the same episodes: one batch of ``--episodes`` envs
of the native vector env, env ``i`` seeded ``seed + i``, so every controller
sees the same randomized drives, WG start angles and target speeds. The env
is the one stored in the policy zip (or ``--config``). The policy acts with
the config's action repeat; every classical controller acts every control
period (its ``dt`` is the env's ``ctrl_dt``).

Per episode, from the env's ``info`` (true states):

* success: the task's (the target reached by the deadline, |flexspline
  torque| never above the rating; an episode over the rating ends there);
* reached: the motor speed, filtered with 25 ms, comes within 5 % of the
  target at some time (``time to target`` is the first such time);
* trapped: the speed averaged over 50 ms never exceeds 9,000 deg/s (the
  2x-order trap sits near 8,000 deg/s);
* peak torque: the largest |flexspline torque| in the episode.

Controllers: ``policy`` (the SB3 model, deterministic), ``pi`` (PI speed
loop, :mod:`agents.baselines`, limited by the amplifier's current and
back-EMF limits), ``pi@XA`` (the same PI with its output limited to X A,
e.g. a continuous current rating; never above the amplifier's limit),
``full`` (constant full current), ``const@X`` (constant X times full
current) and ``const@XA`` (constant X A; above the amplifier's limit it
saturates there). "The amplifier" is the env's: for
``HarmonicDriveResonance-v0`` the preset's (6 A on tuttle-joint1) unless the
config sets ``current_limit`` (3.7 A: the trap-only variant).
``ripple@a,phi`` and ``damp@a,phi`` are full current shaped against the
vibration (:class:`~agents.baselines.RippleCurrent`,
:class:`~agents.baselines.DampingCurrent`, acting every control period
like all classical controllers here).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from agents.baselines import ConstantCurrent, DampingCurrent, PISpeedController, RippleCurrent
from agents.common import env_kwargs, load_config, load_policy, policy_config
from agents.front import wilson

SMOOTH_S = 0.05
TRAP_SPEED = math.radians(9000.0)


@dataclass
class EpisodeStats:
    controller: str
    episodes: int
    success: float  # fraction: the task's success (deadline and rating)
    success_ci: tuple[float, float]  # 95 % Wilson interval
    reached: float  # fraction
    trapped: float  # fraction
    time_to_target_s: float  # s, mean over reached episodes (nan if none)
    peak_torque_mean: float  # N m, mean over episodes of the episode peak
    peak_torque_max: float  # N m
    max_speed_deg_s: float  # mean over episodes of the highest averaged speed
    terminated: float  # fraction ended by the env's safety limits


def make_batch_env(cfg: dict[str, Any], n: int, seed: int) -> Any:
    """The native vector env of a config: ``n`` envs, env ``i`` reset with ``seed + i``."""
    e = cfg["env"]
    venv = gym.make_vec(e["id"], num_envs=n, vectorization_mode="vector_entry_point",
                        max_episode_steps=int(e["max_episode_steps"]), **env_kwargs(cfg))
    return venv


def controller_period(name: str, cfg: dict[str, Any]) -> int:
    """Control periods between a controller's decisions: the policy's action repeat, 1 for
    every classical controller (their dt is the env's control period)."""
    return int(cfg["env"]["action_repeat"]) if name.startswith("policy") else 1


def controller_for(name: str, venv: Any, model: Any = None) -> Any:
    """A controller object with ``predict`` from a controller name (classical controllers
    are built for a call every control period, see :func:`controller_period`)."""
    u = venv.unwrapped if hasattr(venv, "unwrapped") else venv
    b = u.batch
    if name.startswith("policy"):
        if model is None:
            raise ValueError("controller 'policy' needs --policy")
        return model
    if name == "pi" or name.startswith("pi@"):
        limit = None
        if name.startswith("pi@"):
            limit = float(name[3:].rstrip("A"))
        return PISpeedController(u.params, b.speed_scale, b.ctrl_dt, current_limit=limit)
    if name == "full":
        return ConstantCurrent(1.0)
    if name.startswith("const@"):
        spec = name[6:]
        if spec.endswith("A"):  # amps
            return ConstantCurrent(float(spec[:-1]) / b.current_limit)
        return ConstantCurrent(float(spec))
    if name.startswith(("ripple@", "damp@")):
        kind, _, spec = name.partition("@")
        try:
            amp, phase = (float(v) for v in spec.split(","))
        except ValueError:
            raise ValueError(f"{name!r}: use {kind}@<amplitude>,<phase deg>") from None
        if kind == "ripple":
            return RippleCurrent(amp, phase)
        return DampingCurrent(amp, phase, b.ctrl_dt)
    raise ValueError(f"unknown controller {name!r}; use policy, pi, pi@<A>, full, "
                     "const@<x>, const@<A>A, ripple@<a>,<deg> or damp@<a>,<deg>")


def run_episodes(cfg: dict[str, Any], controller: Any, n: int, seed: int, repeat: int = 1
                 ) -> dict[str, np.ndarray]:
    """One episode in each of ``n`` batched envs, the controller acting every ``repeat``
    periods; returns per-period traces ``(n, T)`` and per-episode results.

    Keys: ``time``, ``speed`` (true motor speed, rad/s), ``torque`` (true
    flexspline torque, N m), ``current`` (true motor current, A),
    ``target`` (rad/s), ``length`` (periods), ``terminated`` (bool), and the
    env's ``time_to_target`` (s, NaN if never), ``peak_torque`` (N m) and
    ``success`` (bool), per episode.
    """
    venv = make_batch_env(cfg, n, seed)
    u = venv.unwrapped if hasattr(venv, "unwrapped") else venv
    steps = int(cfg["env"]["max_episode_steps"])
    obs, info = venv.reset(seed=seed)
    if hasattr(controller, "reset"):
        controller.reset(n)
    speed = np.zeros((n, steps))
    torque = np.zeros((n, steps))
    current = np.zeros((n, steps))
    target = np.asarray(info["target_speed"], dtype=float).copy()
    length = np.full(n, steps)
    terminated = np.zeros(n, dtype=bool)
    ttt = np.full(n, np.nan)
    peak = np.zeros(n)
    ok = np.zeros(n, dtype=bool)
    alive = np.ones(n, dtype=bool)
    first = np.ones(n, dtype=bool)
    action = np.zeros((n, 1), dtype=np.float32)
    for k in range(steps):
        if k % repeat == 0:
            a, _ = controller.predict(obs, episode_start=first, deterministic=True)
            action = np.asarray(a, dtype=np.float32).reshape(n, 1)
            first[:] = False
        obs, _r, term, trunc, info = venv.step(action)
        speed[alive, k] = info["motor_velocity"][alive]
        torque[alive, k] = info["output_torque"][alive]
        current[alive, k] = info["motor_current"][alive]
        ended = alive & (term | trunc)
        length[ended] = k + 1
        terminated |= ended & term
        ttt[ended] = np.where(info["time_to_target"][ended] >= 0,
                                      info["time_to_target"][ended], np.nan)
        peak[ended] = info["peak_torque"][ended]
        ok[ended] = info["success"][ended] > 0.5
        alive &= ~ended
        if not alive.any():
            break
    venv.close()
    time = np.arange(1, steps + 1) * u.batch.ctrl_dt
    return {"time": time, "speed": speed, "torque": torque, "current": current,
            "target": target, "length": length, "terminated": terminated,
            "time_to_target": ttt, "peak_torque": peak, "success": ok}


def smoothed(speed: np.ndarray, dt: float) -> np.ndarray:
    """Trailing mean over :data:`SMOOTH_S` along the last axis."""
    w = max(int(round(SMOOTH_S / dt)), 1)
    c = np.cumsum(speed, axis=-1)
    out = np.empty_like(speed)
    out[..., :w] = c[..., :w] / np.arange(1, w + 1)
    out[..., w:] = (c[..., w:] - c[..., :-w]) / w
    return out


def episode_metrics(tr: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per-episode success / reached / time to target / trapped / peak torque / max speed."""
    dt = float(tr["time"][1] - tr["time"][0])
    ws = smoothed(tr["speed"], dt)
    n, steps = ws.shape
    valid = np.arange(steps)[None, :] < tr["length"][:, None]
    wmax = np.where(valid, ws, -np.inf).max(axis=1)
    reached = np.isfinite(tr["time_to_target"])
    return {"success": tr["success"], "reached": reached,
            "time_to_target": tr["time_to_target"], "trapped": wmax < TRAP_SPEED,
            "peak_torque": tr["peak_torque"], "max_speed": wmax,
            "terminated": tr["terminated"]}


def summarize(name: str, m: dict[str, np.ndarray]) -> EpisodeStats:
    n = m["reached"].size
    tt = m["time_to_target"][m["reached"]]
    return EpisodeStats(
        controller=name, episodes=n, success=float(m["success"].mean()),
        success_ci=wilson(float(m["success"].sum()), n), reached=float(m["reached"].mean()),
        trapped=float(m["trapped"].mean()),
        time_to_target_s=float(tt.mean()) if tt.size else float("nan"),
        peak_torque_mean=float(m["peak_torque"].mean()),
        peak_torque_max=float(m["peak_torque"].max()),
        max_speed_deg_s=float(np.degrees(m["max_speed"]).mean()),
        terminated=float(m["terminated"].mean()))


def evaluate(cfg: dict[str, Any], controllers: list[str], n: int, seed: int,
             model: Any = None) -> tuple[list[EpisodeStats], dict[str, dict[str, np.ndarray]]]:
    """Stats and traces of each controller on the same ``n`` episodes."""
    stats, traces = [], {}
    for name in controllers:
        probe = make_batch_env(cfg, 1, seed)
        ctl = controller_for(name, probe, model)
        probe.close()
        tr = run_episodes(cfg, ctl, n, seed, controller_period(name, cfg))
        traces[name] = tr
        stats.append(summarize(name, episode_metrics(tr)))
    return stats, traces


LABELS = {"policy": "PPO policy", "pi": "PI speed loop (amplifier limits)",
          "full": "constant full current"}


def label(name: str) -> str:
    if name in LABELS:
        return LABELS[name]
    if name.startswith("policy-"):
        return f"PPO policy ({name[7:]})"
    if name.startswith("pi@"):
        return f"PI speed loop, output limited to {name[3:].rstrip('A')} A"
    if name.startswith("const@"):
        spec = name[6:]
        return f"constant {spec[:-1]} A" if spec.endswith("A") else \
            f"constant {spec} x full current"
    if name.startswith("ripple@"):
        a, phi = name[7:].split(",")
        return f"full current - {a} + {a} cos(2 theta_wg + {phi} deg)"
    if name.startswith("damp@"):
        a, phi = name[5:].split(",")
        return f"full current - {a} + {a} tanh(torsion feedback at {phi} deg)"
    return name


def markdown_table(stats: list[EpisodeStats], policy_label: str | None = None) -> str:
    rows = ["| controller | episodes | success (95 % CI) | reached target | trapped < 9,000 "
            "deg/s | mean time to target (s) | peak flexspline torque, mean / max (N m) | "
            "highest speed, mean (deg/s) | safety stops |",
            "|---|---|---|---|---|---|---|---|---|"]
    for s in stats:
        tt = "-" if math.isnan(s.time_to_target_s) else f"{s.time_to_target_s:.2f}"
        name = policy_label if s.controller == "policy" and policy_label else label(s.controller)
        lo, hi = s.success_ci
        rows.append(f"| {name} | {s.episodes} | {100 * s.success:.0f} % ({100 * lo:.0f}-"
                    f"{100 * hi:.0f}) | {100 * s.reached:.0f} % | "
                    f"{100 * s.trapped:.0f} % | {tt} | {s.peak_torque_mean:.0f} / "
                    f"{s.peak_torque_max:.0f} | {s.max_speed_deg_s:,.0f} | "
                    f"{100 * s.terminated:.0f} % |")
    return "\n".join(rows) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m agents.evaluate", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--policy", type=Path, help="saved SB3 policy zip")
    ap.add_argument("--config", help="env config (default: the one stored in the policy, "
                    "else resonance_ppo)")
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--controllers", nargs="+",
                    help="default: policy (with --policy), pi, full")
    ap.add_argument("--out", type=Path, help="write the table (.md) and stats (.json) here")
    args = ap.parse_args(argv)
    try:
        if args.episodes < 1:
            raise ValueError(f"--episodes must be >= 1, got {args.episodes}")
        model, cfg = None, None
        if args.policy is not None:
            if not args.policy.is_file():
                raise ValueError(f"--policy: no such file {str(args.policy)!r}")
            model = load_policy(args.policy)
            cfg = policy_config(args.policy)
        if args.config or cfg is None:
            cfg = load_config(args.config or "resonance_ppo")
        names = args.controllers or (["policy"] if model is not None else []) + ["pi", "full"]
        stats, _ = evaluate(cfg, names, args.episodes, args.seed, model)
    except ValueError as exc:
        print(f"agents.evaluate: {exc}", file=sys.stderr)
        return 2
    table = markdown_table(stats, None if model is None else f"{type(model).__name__} policy")
    print(table)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.with_suffix(".md").write_text(table)
        args.out.with_suffix(".json").write_text(
            json.dumps([asdict(s) for s in stats], indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
