"""Gymnasium environments of hdgym.

``import hdgym`` registers:

* ``HarmonicDriveJoint-v0``: output position tracking
  (:class:`~hdgym.envs.joint.HarmonicDriveJointEnv`);
* ``HarmonicDriveResonance-v0``: run-up through the resonance trap by a
  deadline within the gear rating
  (:class:`~hdgym.envs.resonance.HarmonicDriveResonanceEnv`), with the
  variants ``HarmonicDriveResonanceLong-v0`` (6 s episodes, 3.5 s deadline) and
  ``HarmonicDriveResonanceNoTorqueSensor-v0`` (no torque sensor);

each with a native vector env (:mod:`hdgym.envs.vector`) for
``gym.make_vec(..., vectorization_mode="vector_entry_point")``.
"""

from __future__ import annotations

from typing import Any

#: registered ids -> (entry point, vector entry point)
ENV_IDS: dict[str, tuple[str, str]] = {
    "HarmonicDriveJoint-v0": ("hdgym.envs.joint:HarmonicDriveJointEnv",
                              "hdgym.envs.vector:make_joint_vector"),
    "HarmonicDriveResonance-v0": ("hdgym.envs.resonance:HarmonicDriveResonanceEnv",
                                  "hdgym.envs.vector:make_resonance_vector"),
    "HarmonicDriveResonanceLong-v0": ("hdgym.envs.resonance:HarmonicDriveResonanceEnv",
                                      "hdgym.envs.vector:make_resonance_vector"),
    "HarmonicDriveResonanceNoTorqueSensor-v0": ("hdgym.envs.resonance:HarmonicDriveResonanceEnv",
                                                "hdgym.envs.vector:make_resonance_vector"),
}
MAX_EPISODE_STEPS = 2000
#: control periods per episode of the resonance task and its variants (3 s at 1 ms)
RESONANCE_EPISODE_STEPS = 3000
#: control periods per episode of ``HarmonicDriveResonanceLong-v0`` (6 s at 1 ms)
LONG_EPISODE_STEPS = 6000
#: registered variants of the resonance task: id -> keyword arguments. The Long variant's
#: deadline and episode are hdgym.envs.resonance's LONG_DEADLINE and LONG_EPISODE, written
#: out here so that registering stays light; agents.rules.registered checks that they agree.
#: Its time observation keeps the default horizon (3 s; it saturates there), so a policy
#: trained on the default variant sees on it what it saw in training.
RESONANCE_VARIANTS: dict[str, dict[str, Any]] = {
    "HarmonicDriveResonance-v0": {},
    "HarmonicDriveResonanceLong-v0": {"deadline": 3.5},
    "HarmonicDriveResonanceNoTorqueSensor-v0": {"sensors": {"torque_sensor": False}},
}
#: registered variants -> control periods per episode
RESONANCE_STEPS: dict[str, int] = {k: RESONANCE_EPISODE_STEPS for k in RESONANCE_VARIANTS}
RESONANCE_STEPS["HarmonicDriveResonanceLong-v0"] = LONG_EPISODE_STEPS


def register_envs() -> None:
    """Register the hdgym ids with Gymnasium (safe to call more than once)."""
    import gymnasium as gym

    for env_id, (entry, vector_entry) in ENV_IDS.items():
        if env_id in gym.registry:
            continue
        if env_id in RESONANCE_VARIANTS:
            gym.register(id=env_id, entry_point=entry, vector_entry_point=vector_entry,
                         max_episode_steps=RESONANCE_STEPS[env_id],
                         kwargs=dict(RESONANCE_VARIANTS[env_id]))
        else:
            gym.register(id=env_id, entry_point=entry, vector_entry_point=vector_entry,
                         max_episode_steps=MAX_EPISODE_STEPS)


def __getattr__(name: str) -> Any:  # lazy: importing hdgym stays light
    if name == "HarmonicDriveJointEnv":
        from hdgym.envs.joint import HarmonicDriveJointEnv
        return HarmonicDriveJointEnv
    if name == "HarmonicDriveResonanceEnv":
        from hdgym.envs.resonance import HarmonicDriveResonanceEnv
        return HarmonicDriveResonanceEnv
    if name == "HarmonicDriveVectorEnv":
        from hdgym.envs.vector import HarmonicDriveVectorEnv
        return HarmonicDriveVectorEnv
    raise AttributeError(f"module 'hdgym.envs' has no attribute {name!r}")


__all__ = ["ENV_IDS", "HarmonicDriveJointEnv", "HarmonicDriveResonanceEnv",
           "HarmonicDriveVectorEnv", "MAX_EPISODE_STEPS", "register_envs"]
