"""Stable-Baselines3 agents for the hdgym envs.

* :mod:`agents.train`: ``python -m agents.train --algo ppo`` (configs in
  ``agents/configs/``);
* :mod:`agents.evaluate`: ``python -m agents.evaluate --policy PATH.zip``;
* :mod:`agents.baselines`: PI speed loop designed with python-control,
  constant current;
* :mod:`agents.report`: writes ``results/rl/``;
* :mod:`agents.vec_env`: :class:`~agents.vec_env.HarmonicDriveVecEnv`, an
  SB3 ``VecEnv`` over the native batched env;
* :mod:`agents.bench`: SB3 training throughput for ``hdgym bench``.

The committed policy ``agents/policies/resonance_ppo.zip`` crosses the
resonance trap of ``HarmonicDriveResonance-v0``.
"""
