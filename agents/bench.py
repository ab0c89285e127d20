"""SB3 training throughput for ``hdgym bench``, measured side by side in one run.

hdgym finds this module through the entry point ``agents = "agents.bench"`` of
the group ``hdgym.bench_sections`` (see :mod:`hdgym.plugins`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import gymnasium as gym

from agents.vec_env import HarmonicDriveVecEnv
from hdgym.bench import register_section
from hdgym.envs.bench import JOINT, compare_rates


@register_section("Stable-Baselines3 training", order=30)
def bench_sb3(quick: bool = False, **kw: Any) -> list[dict[str, Any]]:
    """PPO (SB3) training throughput on :class:`~agents.vec_env.HarmonicDriveVecEnv`
    against a DummyVecEnv of single envs, 16 envs each (rollouts and updates, the
    whole ``learn`` call). ``kw`` goes to the envs."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv

    n, total = 16, (2048 if quick else 16384)
    ppo = {"n_steps": 128, "batch_size": 512, "n_epochs": 2, "seed": 0, "device": "cpu"}

    def learner(make_venv: Callable[[], Any]) -> Callable[[], int]:
        def run() -> int:
            venv = make_venv()
            model = PPO("MlpPolicy", venv, **ppo)
            model.learn(total)
            venv.close()
            return model.num_timesteps
        return run

    native = learner(lambda: HarmonicDriveVecEnv(JOINT, num_envs=n, **kw))
    dummy = learner(lambda: DummyVecEnv([lambda: gym.make(JOINT, **kw) for _ in range(n)]))
    row = compare_rates(f"PPO training on HarmonicDriveVecEnv x{n} (agents.vec_env)",
                        f"PPO training on DummyVecEnv({JOINT}) x{n}", 1.0, native, dummy,
                        repeats=1)
    row["note"] = (f"PPO from Stable-Baselines3, {total:,} env steps per run, rollouts of "
                   f"{ppo['n_steps']} steps, {ppo['n_epochs']} epochs per update on the CPU; "
                   "env-steps/s of the whole learn() call, updates included")
    return [row, bench_resonance_training(quick)]


def bench_resonance_training(quick: bool = False) -> dict[str, Any]:
    """The committed resonance config's PPO training (agents/configs/resonance_ppo.toml:
    hold of 5 periods, torque penalty) on the native batch against the setup it replaced,
    8 wrapped single envs (ActionRepeat, TorquePenalty, Monitor) in a DummyVecEnv."""
    import copy

    import torch

    from agents.common import load_config, make_vec_env
    from agents.train import build_model

    torch.set_num_threads(1)
    cfg = load_config("resonance_ppo")
    total = 4096 if quick else 32768

    def learner(kind: str, n_envs: int) -> Callable[[], int]:
        def run() -> int:
            c = copy.deepcopy(cfg)
            venv = make_vec_env(c, n_envs, 0, None, kind)
            model = build_model(c, venv, 0, None)
            model.learn(total)
            venv.close()
            return model.num_timesteps
        return run

    n = int(cfg["train"]["n_envs"])
    row = compare_rates(f"resonance_ppo training, native batch x{n} (hold and penalty in the "
                        "batch)", "the same config on DummyVecEnv x8 of wrapped single envs "
                        "(before this change)", 2.0, learner("native", n),
                        learner("dummy", 8), repeats=1)
    row["unit"] = "agent-steps/s"
    row["note"] = (f"agents.train's model and config (PPO, rollouts of "
                   f"{cfg['algo']['n_steps']} agent steps per env, {cfg['algo']['n_epochs']} "
                   f"epochs, batch {cfg['algo']['batch_size']}), {total:,} agent steps of 5 "
                   "control periods per run, whole learn() call; target 2: the 800k-step run "
                   "took 4.9 min on DummyVecEnv x8 before, the goal is <= 5 min with room to spare")
    return row
