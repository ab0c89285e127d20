"""Stable-Baselines3 agents for the hdgym envs.

* :mod:`agents.train`: ``python -m agents.train --algo ppo`` (configs in
  ``agents/configs/``);
* :mod:`agents.evaluate`: ``python -m agents.evaluate --policy PATH.zip``;
* :mod:`agents.baselines`: PI speed loop designed with python-control,
  constant current;
* :mod:`agents.families`: the classical controller families with per-env
  parameters (a whole tuning grid is one native batch);
* :mod:`agents.front`: ``python -m agents.front``: tune the families on
  training episodes, their success front on held-out episodes;
* :mod:`agents.rules`: the rules that pick the task's deadline and gear
  rating from the measured front;
* :mod:`agents.benchmark`: ``python -m agents.benchmark``: fronts, rules,
  check of the registered constants, training, ``results/rl/`` in one command;
* :mod:`agents.report`: writes ``results/rl/`` (:mod:`agents.other_joints`:
  its section on joints 2 and 3);
* :mod:`agents.vec_env`: :class:`~agents.vec_env.HarmonicDriveVecEnv`, an
  SB3 ``VecEnv`` over the native batched env;
* :mod:`agents.bench`: SB3 training throughput for ``hdgym bench``.

The committed policies ``agents/policies/resonance_ppo.zip`` and
``resonance_ppo_notorque.zip`` solve ``HarmonicDriveResonance-v0`` and its
no-torque-sensor variant; ``results/rl/evaluation.md`` compares them with the
tuned classical controllers.
"""
