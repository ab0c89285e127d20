"""The ``rl_train`` scenario of ``hdgym sweep``: train and evaluate one policy per job.

hdgym finds this module through the entry point ``agents = "agents.sweep"``
of the group ``hdgym.sweep_scenarios`` (see :mod:`hdgym.plugins`); importing
it registers the scenario. Stable-Baselines3 (the ``[rl]`` extra) is
imported only when a job runs, so a spec naming ``rl_train`` is checked even
without it.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from agents.common import config_path, load_config, load_policy
from hdgym.params import JointParams
from hdgym.sweep.scenarios import OptionError, register

RL_KEYS = {"name": "", "config": "", "total_timesteps": 0, "quick_timesteps": 0, "n_envs": 0,
           "eval_episodes": 0, "randomize": {}}
RL_QUICK_TIMESTEPS = 2048
RL_EVAL_EPISODES = 8
RL_QUICK_EVAL_EPISODES = 4


def _check_agent(config: Mapping[str, Any]) -> None:
    for key, value in config.items():
        if key not in RL_KEYS:
            raise OptionError(f"unknown key {key!r}; known: {', '.join(sorted(RL_KEYS))}", key)
        default = RL_KEYS[key]
        if isinstance(default, int) and not (isinstance(value, int) and not isinstance(value, bool)
                                             and value > 0):
            raise OptionError(f"{key} must be a whole number > 0, got {value!r}", key)
        if isinstance(default, dict) and not isinstance(value, dict):
            raise OptionError(f"{key} must be a table of dotted path = spread", key)
    if "config" not in config or not isinstance(config["config"], str):
        raise OptionError("needs config = \"<bundled agents config name or .toml path>\"",
                          "name")
    try:
        config_path(config["config"])
    except ValueError as exc:
        raise OptionError(str(exc), "config") from None


#: what a trained policy's metrics depend on besides the drive: the env's task
#: (targets, deadline, rating, reward: hdgym/envs) and the training and evaluation code
_TASK_SOURCES = (Path(__file__).resolve().parent,
                 Path(__file__).resolve().parent.parent / "hdgym" / "envs")


def task_digest(agent: Mapping[str, Any] | None) -> str:
    """16 hex digits over the agent config file's text, the env package's and the
    agents package's sources: a resumed sweep reruns its ``rl_train`` jobs when
    the task (e.g. ``DEADLINE`` or ``GEAR_RATINGS``), the training code or the
    config changes."""
    h = hashlib.sha256()
    if agent and isinstance(agent.get("config"), str):
        h.update(config_path(agent["config"]).read_bytes() + b"\0")
    for root in _TASK_SOURCES:
        for f in sorted(root.rglob("*.py")):
            h.update(f.relative_to(root.parent).as_posix().encode() + b"\0")
            h.update(f.read_bytes() + b"\0")
    return h.hexdigest()[:16]


@register("rl_train", needs="agent", options={}, check_slot=_check_agent,
          task_digest=task_digest)
def rl_train(params: JointParams, job: Any) -> dict[str, float]:
    """Train an SB3 policy on the job's drive and evaluate it: ``success`` (the task's:
    the target by the deadline within the rating), ``reached``, ``trapped``,
    ``terminated`` (fractions of episodes), ``time_to_target_s`` (s), ``peak_torque_mean``,
    ``peak_torque_max`` (N m, flexspline), ``max_speed_deg_s`` (deg/s), ``agent_steps``.

    Training is :func:`agents.train.train`, evaluation :func:`agents.evaluate.evaluate`.

    One job per ``[[agents]]`` config and seed. The config's env runs on the
    job's (randomized) drive; the SB3 seed is the job's seed, as
    ``python -m agents.train --seed N``. ``quick`` trains ``quick_timesteps``
    (default 2048) agent steps. The policy goes to
    ``DIR/jobs/<job_id>/final.zip``. Evaluation runs ``eval_episodes``
    episodes seeded from the job (default 8, quick 4).
    """
    import copy
    import tempfile
    from pathlib import Path

    from agents.evaluate import evaluate
    from agents.train import train

    agent = dict(job.agent or {})
    cfg = copy.deepcopy(load_config(agent["config"]))
    t = cfg["train"]
    t["seed"] = int(job.seed)
    t["eval_freq"] = 0  # the sweep evaluates once at the end
    t["checkpoint_freq"] = 0
    if job.quick:
        t["total_timesteps"] = int(agent.get("quick_timesteps", RL_QUICK_TIMESTEPS))
    elif "total_timesteps" in agent:
        t["total_timesteps"] = int(agent["total_timesteps"])
    if "n_envs" in agent:
        t["n_envs"] = int(agent["n_envs"])
    kw = cfg["env"].setdefault("kwargs", {})
    kw["preset"] = params
    if "randomize" in agent:
        kw["randomize"] = dict(agent["randomize"])
    n_eval = int(agent.get("eval_episodes",
                           RL_QUICK_EVAL_EPISODES if job.quick else RL_EVAL_EPISODES))
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(job.workdir) / job.job_id if job.workdir else Path(tmp)
        summary = train(cfg, out, progress=False)
        model = load_policy(out / "final.zip")  # train.json names it relative to the cwd
        stats, _ = evaluate(cfg, ["policy"], n_eval, 1_000_000 + job.run_seed() % 1_000_000,
                            model)
    s = stats[0]
    return {"success": s.success, "reached": s.reached, "trapped": s.trapped,
            "terminated": s.terminated,
            "time_to_target_s": s.time_to_target_s, "peak_torque_mean": s.peak_torque_mean,
            "peak_torque_max": s.peak_torque_max, "max_speed_deg_s": s.max_speed_deg_s,
            "agent_steps": float(summary["agent_steps"])}
