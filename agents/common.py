"""Shared plumbing of agents: configs, env construction, policy files.

A config is a TOML file (see ``agents/configs/``) with the tables

* ``[env]``: ``id``, ``max_episode_steps``, ``action_repeat`` (control
  periods per agent decision; the action is held, the rewards averaged)
  optionally ``[env.torque_penalty]`` (``weight``, ``threshold`` in N m:
  agent-side reward shaping, see :class:`TorquePenalty`) and
  ``[env.kwargs]`` passed to ``gym.make`` (SI units, e.g.
  ``target_speed`` in rad/s, ``[env.kwargs.randomize]`` relative spreads
  per dotted parameter path);
* ``[train]``: ``algo`` (``ppo`` or ``sac``), ``total_timesteps``,
  ``n_envs``, ``vec_env`` (``native``: one batch of the compiled env,
  the default; ``dummy`` or ``subproc``: a Python env per joint), ``seed``,
  ``eval_freq``, ``eval_episodes``, ``checkpoint_freq`` (env steps);
* ``[policy]``: ``net_arch`` (hidden layer sizes), ``log_std_init``,
  ``history`` (the policy sees its last ``history`` observations stacked, each
  with the action before it; default 1) and ``normalize_obs`` (the policy
  sees the observation standardized by its running mean and variance over
  training, SB3's ``VecNormalize``; default false), see :class:`ObsPipeline`;
* ``[algo]``: keyword arguments of the SB3 algorithm.

The resolved config is stored inside the saved policy zip
(``agents_config.json``) so :mod:`agents.evaluate` rebuilds the same env.
"""

from __future__ import annotations

import copy
import json
import math
import tomllib
import zipfile
from collections.abc import Callable, Mapping
from importlib import resources
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import hdgym  # noqa: F401  (registers the env ids)
from hdgym.files import atomic_path

CONFIG_MEMBER = "agents_config.json"
#: the observation pipeline's numbers (history, normalization statistics) in a policy zip
PIPELINE_MEMBER = "agents_obs_pipeline.json"
DEFAULT_CONFIGS = {"ppo": "resonance_ppo", "sac": "resonance_sac"}


def config_path(name: str | Path) -> Path:
    """A config file path, or the name of a bundled config (``resonance_ppo``)."""
    p = Path(name)
    if p.suffix == ".toml" and p.exists():
        return p
    bundled = resources.files("agents").joinpath("configs", f"{Path(name).stem}.toml")
    if bundled.is_file():
        return Path(str(bundled))
    raise ValueError(f"config: no such file or bundled config {str(name)!r}")


def load_config(name: str | Path) -> dict[str, Any]:
    """Read a config TOML (path or bundled name) into a dict, with defaults filled in."""
    path = config_path(name)
    try:
        cfg = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not valid TOML: {exc}") from None
    cfg.setdefault("env", {})
    cfg["env"].setdefault("id", "HarmonicDriveResonance-v0")
    cfg["env"].setdefault("max_episode_steps", 2000)
    cfg["env"].setdefault("action_repeat", 1)
    cfg["env"].setdefault("kwargs", {})
    cfg.setdefault("train", {})
    t = cfg["train"]
    t.setdefault("algo", "ppo")
    t.setdefault("total_timesteps", 100_000)
    t.setdefault("n_envs", 4)
    t.setdefault("vec_env", "native")
    t.setdefault("seed", 0)
    t.setdefault("eval_freq", 0)
    t.setdefault("eval_episodes", 8)
    t.setdefault("checkpoint_freq", 0)
    cfg.setdefault("policy", {})
    cfg.setdefault("algo", {})
    cfg["source"] = str(path)
    return cfg


def env_kwargs(cfg: Mapping[str, Any]) -> dict[str, Any]:
    """``gym.make`` keyword arguments of a config (lists become tuples)."""
    kw = copy.deepcopy(dict(cfg["env"].get("kwargs", {})))
    if isinstance(kw.get("target_speed"), list):
        kw["target_speed"] = tuple(kw["target_speed"])
    return kw


class ActionRepeat(gym.Wrapper):
    """Hold each action for ``repeat`` control periods; the reward is their mean.

    The episode ends at the first period that ends it; ``info`` is the last
    period's.
    """

    def __init__(self, env: gym.Env, repeat: int) -> None:
        super().__init__(env)
        if int(repeat) != repeat or repeat < 1:
            raise ValueError(f"action_repeat must be a whole number >= 1, got {repeat!r}")
        self.repeat = int(repeat)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        total, count = 0.0, 0
        for _ in range(self.repeat):
            obs, r, term, trunc, info = self.env.step(action)
            total += float(r)
            count += 1
            if term or trunc:
                break
        return obs, total / count, term, trunc, info


class TorquePenalty(gym.Wrapper):
    """Reward shaping on the peak flexspline torque (training only).

    Each control period subtracts ``weight * max(0, |T_k| / threshold - 1)^2``
    (true flexspline torque from ``info``). The env's own oscillation cost
    saturates at twice its torque scale, so it cannot tell a 150 N m peak
    from a 300 N m one; this term can.
    """

    def __init__(self, env: gym.Env, weight: float, threshold: float) -> None:
        super().__init__(env)
        if not (weight >= 0 and threshold > 0):
            raise ValueError(f"torque_penalty needs weight >= 0 and threshold > 0 N m, got "
                             f"{weight!r}, {threshold!r}")
        self.weight = float(weight)
        self.threshold = float(threshold)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, r, term, trunc, info = self.env.step(action)
        excess = max(0.0, abs(float(info["output_torque"])) / self.threshold - 1.0)
        return obs, float(r) - self.weight * excess * excess, term, trunc, info


def make_env(cfg: Mapping[str, Any], monitor_file: str | None = None,
             extra_kwargs: Mapping[str, Any] | None = None) -> gym.Env:
    """One wrapped env of a config (TimeLimit, TorquePenalty, ActionRepeat, SB3 Monitor)."""
    from stable_baselines3.common.monitor import Monitor

    e = cfg["env"]
    kw = env_kwargs(cfg)
    kw.update(extra_kwargs or {})
    env = gym.make(e["id"], max_episode_steps=int(e["max_episode_steps"]), **kw)
    tp = e.get("torque_penalty")
    if tp:
        env = TorquePenalty(env, float(tp.get("weight", 0.0)), float(tp.get("threshold", 1.0)))
    if int(e["action_repeat"]) > 1:
        env = ActionRepeat(env, int(e["action_repeat"]))
    return Monitor(env, filename=monitor_file)


def make_native_vec_env(cfg: Mapping[str, Any], n_envs: int,
                        extra_kwargs: Mapping[str, Any] | None = None) -> Any:
    """The config's envs as one :class:`~agents.vec_env.HarmonicDriveVecEnv` batch,
    action repeat and torque penalty inside the batch."""
    from agents.vec_env import HarmonicDriveVecEnv

    e = cfg["env"]
    kw = env_kwargs(cfg)
    kw.update(extra_kwargs or {})
    tp = e.get("torque_penalty")
    penalty = (float(tp.get("weight", 0.0)), float(tp.get("threshold", 1.0))) if tp else None
    return HarmonicDriveVecEnv(e["id"], n_envs, action_repeat=int(e["action_repeat"]),
                               torque_penalty=penalty,
                               max_episode_steps=int(e["max_episode_steps"]), **kw)


def make_vec_env(cfg: Mapping[str, Any], n_envs: int, seed: int,
                 monitor_dir: str | Path | None = None, kind: str = "native") -> Any:
    """An SB3 VecEnv of ``n_envs`` configured envs, env ``i`` seeded ``seed + i``.

    ``kind``: ``native`` (one batch of the compiled env, SB3's ``VecMonitor``
    writes ``monitor_dir/native.monitor.csv``), ``dummy`` or ``subproc``
    (one wrapped Python env per joint, :func:`make_env`).
    """
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecMonitor

    if kind == "native":
        venv = make_native_vec_env(cfg, n_envs)
        f = None if monitor_dir is None else str(Path(monitor_dir) / "native")
        venv = VecMonitor(venv, filename=f, info_keywords=("is_success",)
                          if "success" in venv.get_attr("task")[0].aux_names else ())
        venv.seed(seed)
        return venv

    def thunk(i: int) -> Callable[[], gym.Env]:
        def _make() -> gym.Env:
            f = None if monitor_dir is None else str(Path(monitor_dir) / f"env{i}")
            return make_env(cfg, f)
        return _make

    fns = [thunk(i) for i in range(n_envs)]
    if kind == "subproc":
        venv = SubprocVecEnv(fns, start_method="fork")
    elif kind == "dummy":
        venv = DummyVecEnv(fns)
    else:
        raise ValueError(f"vec_env must be 'native', 'dummy' or 'subproc', got {kind!r}")
    venv.seed(seed)
    return venv


def _add_member(zip_path: str | Path, member: str, text: str) -> None:
    """Add ``member`` to a saved SB3 policy zip unless it already holds one.

    The zip is appended to as a copy beside it, renamed over it when complete, so an
    interrupt leaves the policy as it was, never a damaged zip.
    """
    with zipfile.ZipFile(zip_path) as zf:
        if member in zf.namelist():
            return
    data = Path(zip_path).read_bytes()
    with atomic_path(zip_path) as tmp:
        tmp.write_bytes(data)
        with zipfile.ZipFile(tmp, "a", compression=zipfile.ZIP_DEFLATED) as zf:
            zf.writestr(member, text)


def embed_config(zip_path: str | Path, cfg: Mapping[str, Any]) -> None:
    """Store the resolved config inside a saved SB3 policy zip."""
    _add_member(zip_path, CONFIG_MEMBER, json.dumps(cfg, indent=1, default=str))


def policy_config(zip_path: str | Path) -> dict[str, Any] | None:
    """The config stored in a policy zip by :func:`embed_config`, if any."""
    with zipfile.ZipFile(zip_path) as zf:
        if CONFIG_MEMBER not in zf.namelist():
            return None
        return json.loads(zf.read(CONFIG_MEMBER))


def load_policy(path: str | Path) -> Any:
    """Load a saved SB3 model (PPO or SAC, from the stored config) on the CPU; a policy
    trained with a history or normalized observations comes as an :class:`ObsPipeline`
    that feeds it the env's observations the way it saw them in training."""
    from stable_baselines3 import PPO, SAC

    cfg = policy_config(path) or {}
    algo = str(cfg.get("train", {}).get("algo", "ppo")).lower()
    cls = {"ppo": PPO, "sac": SAC}.get(algo)
    if cls is None:
        raise ValueError(f"{path}: unknown algo {algo!r} in the stored config")
    model = cls.load(str(path), device="cpu")
    with zipfile.ZipFile(path) as zf:
        if PIPELINE_MEMBER not in zf.namelist():
            return model
        spec = json.loads(zf.read(PIPELINE_MEMBER))
    return ObsPipeline(model, int(spec["history"]), spec.get("obs_mean"), spec.get("obs_var"),
                       float(spec.get("clip", 10.0)), float(spec.get("epsilon", 1e-8)))


def obs_options(cfg: Mapping[str, Any]) -> tuple[int, bool]:
    """A config's ``[policy]`` ``history`` (>= 1) and ``normalize_obs``."""
    pol = cfg.get("policy", {})
    history = pol.get("history", 1)
    if not (isinstance(history, int) and not isinstance(history, bool) and history >= 1):
        raise ValueError(f"policy.history must be a whole number >= 1, got {history!r}")
    norm = pol.get("normalize_obs", False)
    if not isinstance(norm, bool):
        raise ValueError(f"policy.normalize_obs must be true or false, got {norm!r}")
    return history, norm


def wrap_obs(venv: Any, cfg: Mapping[str, Any], training: bool = True) -> Any:
    """``venv`` with the config's observation pipeline: SB3's ``VecFrameStack`` for a
    history, then ``VecNormalize`` (observations only, the reward as the env's)."""
    from stable_baselines3.common.vec_env import VecFrameStack, VecNormalize

    history, norm = obs_options(cfg)
    if history > 1:
        venv = VecFrameStack(venv, history)
    if norm:
        venv = VecNormalize(venv, training=training, norm_obs=True, norm_reward=False)
    return venv


def save_pipeline(zip_path: str | Path, venv: Any, cfg: Mapping[str, Any]) -> None:
    """Store the observation pipeline (history, normalization statistics of the training
    ``venv``) in a saved policy zip; nothing for a config without one."""
    from stable_baselines3.common.vec_env import VecNormalize

    history, norm = obs_options(cfg)
    if history == 1 and not norm:
        return
    spec: dict[str, Any] = {"history": history}
    if norm:
        v = venv
        while not isinstance(v, VecNormalize):
            v = v.venv
        spec.update(obs_mean=v.obs_rms.mean.tolist(), obs_var=v.obs_rms.var.tolist(),
                    clip=float(v.clip_obs), epsilon=float(v.epsilon))
    _add_member(zip_path, PIPELINE_MEMBER, json.dumps(spec))


class ObsPipeline:
    """A policy fed the way it was trained: the last ``history`` observations stacked
    (oldest first, zeros before an episode's first, as SB3's ``VecFrameStack``), then
    standardized (``(x - mean) / sqrt(var + epsilon)``, clipped to ``clip``, as
    ``VecNormalize``). ``predict`` takes the env's observations like an SB3 model's;
    ``episode_start`` (one flag per env) clears an env's history."""

    def __init__(self, model: Any, history: int, mean: Any = None, var: Any = None,
                 clip: float = 10.0, epsilon: float = 1e-8) -> None:
        self.model = model
        self.history = int(history)
        self.mean = None if mean is None else np.asarray(mean, dtype=np.float64)
        self.std = None if var is None else np.sqrt(np.asarray(var, dtype=np.float64) + epsilon)
        self.clip = clip
        self.stack: np.ndarray | None = None

    def predict(self, obs: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        x = np.asarray(obs, dtype=np.float32)
        single = x.ndim == 1
        x = np.atleast_2d(x)
        n, d = x.shape
        if self.stack is None or self.stack.shape[0] != n:
            self.stack = np.zeros((n, d * self.history), dtype=np.float32)
            episode_start = np.ones(n, dtype=bool)
        if episode_start is not None:
            self.stack[np.asarray(episode_start, dtype=bool).reshape(n)] = 0.0
        self.stack = np.roll(self.stack, -d, axis=1)
        self.stack[:, -d:] = x
        z = self.stack.astype(np.float64)
        if self.mean is not None:
            z = np.clip((z - self.mean) / self.std, -self.clip, self.clip)
        a, s = self.model.predict(z.astype(np.float32), state, deterministic=deterministic)
        return (a[0] if single else a), s


def deg(x: float | np.ndarray) -> float | np.ndarray:
    """rad -> deg (for reports)."""
    return np.degrees(x) if isinstance(x, np.ndarray) else math.degrees(x)
