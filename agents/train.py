"""Train a Stable-Baselines3 policy on an hdgym env.

    python -m agents.train --env HarmonicDriveResonance-v0 --algo ppo
    python -m agents.train --config resonance_sac --seed 1 --total-timesteps 50000 --out runs/sac

Writes to ``--out`` (default ``runs/<config>-s<seed>``): TensorBoard logs
(``tb/``), SB3 monitor files of the training envs (``monitor/``), the
periodic evaluation (``eval/evaluations.npz``, best model in ``best/``),
checkpoints (``checkpoints/``), the final policy ``final.zip`` (with the
resolved config inside) and ``train.json`` (wall time, steps per second).
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import time
from pathlib import Path
from typing import Any

from agents.common import (
    DEFAULT_CONFIGS,
    embed_config,
    load_config,
    make_vec_env,
    save_pipeline,
    wrap_obs,
)


def shown(path: str | Path) -> str:
    """``path`` as reports name it: relative to the working folder or to the checkout."""
    p = Path(path).resolve()
    for base in (Path.cwd(), Path(__file__).resolve().parents[1]):
        if p.is_relative_to(base):
            return p.relative_to(base).as_posix()
    return p.name


def build_model(cfg: dict[str, Any], venv: Any, seed: int, tb_dir: str | None) -> Any:
    """The SB3 model of a config on ``venv``."""
    from stable_baselines3 import PPO, SAC

    algo = cfg["train"]["algo"].lower()
    pol = dict(cfg.get("policy", {}))
    policy_kwargs: dict[str, Any] = {}
    if "net_arch" in pol:
        policy_kwargs["net_arch"] = list(pol["net_arch"])
    if "log_std_init" in pol:
        policy_kwargs["log_std_init"] = float(pol["log_std_init"])
    kwargs = dict(cfg.get("algo", {}))
    cls = {"ppo": PPO, "sac": SAC}.get(algo)
    if cls is None:
        raise ValueError(f"algo must be 'ppo' or 'sac', got {algo!r}")
    return cls("MlpPolicy", venv, seed=seed, tensorboard_log=tb_dir, device="cpu", verbose=0,
               policy_kwargs=policy_kwargs, **kwargs)


def train(cfg: dict[str, Any], out: Path, progress: bool = True) -> dict[str, Any]:
    """Train per ``cfg`` into ``out``; returns the summary written to ``train.json``."""
    import torch
    from stable_baselines3.common.callbacks import CheckpointCallback, EvalCallback

    torch.set_num_threads(1)
    t = cfg["train"]
    n_envs, seed = int(t["n_envs"]), int(t["seed"])
    out.mkdir(parents=True, exist_ok=True)
    (out / "monitor").mkdir(exist_ok=True)
    venv = wrap_obs(make_vec_env(cfg, n_envs, seed, out / "monitor", t["vec_env"]), cfg)
    model = build_model(cfg, venv, seed, str(out / "tb"))
    callbacks = []
    if int(t["checkpoint_freq"]) > 0:
        callbacks.append(CheckpointCallback(max(int(t["checkpoint_freq"]) // n_envs, 1),
                                            str(out / "checkpoints"), name_prefix="policy"))
    eval_env = None
    if int(t["eval_freq"]) > 0:
        n_eval = int(t["eval_episodes"])
        eval_env = wrap_obs(make_vec_env(cfg, n_eval, seed + 10_000, None, t["vec_env"]), cfg,
                            training=False)
        callbacks.append(EvalCallback(eval_env, n_eval_episodes=n_eval,
                                      eval_freq=max(int(t["eval_freq"]) // n_envs, 1),
                                      log_path=str(out / "eval"),
                                      best_model_save_path=str(out / "best"),
                                      deterministic=True, verbose=0))
    start = time.perf_counter()
    model.learn(total_timesteps=int(t["total_timesteps"]), callback=callbacks,
                progress_bar=progress, tb_log_name=t["algo"])
    wall = time.perf_counter() - start
    final = out / "final.zip"
    model.save(str(final))
    embed_config(final, cfg)
    save_pipeline(final, venv, cfg)
    if (out / "best" / "best_model.zip").exists():
        embed_config(out / "best" / "best_model.zip", cfg)
        save_pipeline(out / "best" / "best_model.zip", venv, cfg)
    venv.close()
    if eval_env is not None:
        eval_env.close()
    steps = int(model.num_timesteps)
    periods = steps * int(cfg["env"]["action_repeat"])
    summary = {"config": shown(cfg["source"]), "algo": t["algo"], "seed": seed, "n_envs": n_envs,
               "agent_steps": steps, "control_periods": periods, "wall_time_s": round(wall, 1),
               "agent_steps_per_s": round(steps / wall, 1),
               "control_periods_per_s": round(periods / wall, 1), "final_policy": shown(final)}
    (out / "train.json").write_text(json.dumps(summary, indent=1) + "\n")
    return summary


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m agents.train", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--env", help="Gymnasium id (default: the config's)")
    ap.add_argument("--algo", choices=("ppo", "sac"), help="picks the bundled config "
                    "resonance_<algo> when --config is not given")
    ap.add_argument("--config", help="config TOML path or bundled name (agents/configs/)")
    ap.add_argument("--seed", type=int)
    ap.add_argument("--total-timesteps", type=int)
    ap.add_argument("--n-envs", type=int)
    ap.add_argument("--vec-env", choices=("native", "dummy", "subproc"))
    ap.add_argument("--out", type=Path,
                    help="run folder (default runs/<config>-s<seed>; removed if the run fails)")
    ap.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = ap.parse_args(argv)
    try:
        cfg = load_config(args.config or DEFAULT_CONFIGS[args.algo or "ppo"])
        if args.algo and cfg["train"]["algo"].lower() != args.algo:
            raise ValueError(f"--algo {args.algo} disagrees with the config's algo "
                             f"{cfg['train']['algo']!r}")
        if args.env:
            cfg["env"]["id"] = args.env
        for key, val in (("seed", args.seed), ("total_timesteps", args.total_timesteps),
                         ("n_envs", args.n_envs), ("vec_env", args.vec_env)):
            if val is not None:
                cfg["train"][key] = val
        name = Path(cfg["source"]).stem
        out = args.out or Path("runs") / f"{name}-s{cfg['train']['seed']}"
        created = not out.exists()
        try:
            summary = train(cfg, out, progress=not args.no_progress)
        except BaseException:  # no half-made run folder is left behind
            if created:
                shutil.rmtree(out, ignore_errors=True)
            raise
    except ValueError as exc:
        print(f"agents.train: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("agents.train: interrupted; no unfinished run folder is kept", file=sys.stderr)
        return 130
    print(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
