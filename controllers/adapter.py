"""Run a controller as a policy on the Gymnasium envs.

:class:`ControllerPolicy` undoes the documented observation normalisation of
``HarmonicDriveJoint-v0`` (:class:`hdgym.envs.joint.HarmonicDriveJointEnv`,
observation table in its docstring; names in ``TrackingTask.obs_names``)
to rebuild the measurement mapping the controller expects, calls it, and
turns the current (A) into the normalized action ``current / I_max``:

| # | observation | measurement |
|---|---|---|
| 0 | output angle / reference_scale | ``output_angle`` |
| 1 | motor angle / ratio / reference_scale | ``motor_angle`` |
| 4 | motor velocity / (V/K_b) | ``motor_velocity`` |
| 5 | output velocity / (V/K_b/ratio) | ``output_velocity`` |
| 6 | torque sensor / (K_t I_max ratio) | ``output_torque`` |
| 7 | motor current / I_max | ``motor_current`` |
| 8 | reference / reference_scale | ``reference`` |

Only measured channels are used (``info`` holds true states and is read
for ``time`` alone, when given). Observations are float32 and clipped to
±10, so angles beyond ``10 * reference_scale`` saturate: keep the
reference scale large enough for the motion.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from controllers.base import Controller, check_positive

#: observation names this adapter reads, by index (TrackingTask.obs_names)
OBS_INDEX = {
    "output_angle": 0, "motor_angle_output_referred": 1, "motor_velocity": 4,
    "output_velocity": 5, "output_torque": 6, "motor_current": 7, "reference": 8,
}


class ControllerPolicy:
    """A controller (measurements → A) as a policy (observation → action).

    Args:
        controller: the controller.
        ratio: nominal motor angle per output angle.
        current_limit: I_max used by the env to scale actions and currents, A.
        reference_scale: the env's ``reference_scale``, output rad.
        speed_scale: motor speed scale ``V/K_b``, rad/s.
        torque_scale: torque scale ``K_t I_max ratio``, N m.
        dt: control period, s.
        obs_names: the env's observation names (checked against the layout).
    """

    def __init__(self, controller: Controller, *, ratio: float, current_limit: float,
                 reference_scale: float, speed_scale: float, torque_scale: float,
                 dt: float, obs_names: tuple[str, ...] | None = None) -> None:
        self.controller = controller
        self.ratio = check_positive("ratio", ratio)
        self.current_limit = check_positive("current_limit", current_limit, "A")
        self.reference_scale = check_positive("reference_scale", reference_scale, "rad")
        self.speed_scale = check_positive("speed_scale", speed_scale, "rad/s")
        self.torque_scale = check_positive("torque_scale", torque_scale, "N m")
        self.dt = check_positive("dt", dt, "s")
        if obs_names is not None:
            for name, k in OBS_INDEX.items():
                if k >= len(obs_names) or obs_names[k] != name:
                    raise ValueError(f"obs_names: expected {name!r} at index {k}, got "
                                     f"{obs_names[k] if k < len(obs_names) else None!r}; "
                                     "the env's observation layout changed")
        self.steps = 0

    @classmethod
    def from_env(cls, env: Any, controller: Controller) -> ControllerPolicy:
        """Read the scales from a ``HarmonicDriveJoint-v0`` env (wrapped or not)."""
        u = env.unwrapped
        b, task = u.batch, u.task
        return cls(controller, ratio=b.ratio, current_limit=b.current_limit,
                   reference_scale=task.reference_scale, speed_scale=b.speed_scale,
                   torque_scale=b.torque_scale, dt=b.ctrl_dt, obs_names=task.obs_names)

    def reset(self) -> None:
        """Call at the start of each episode."""
        self.controller.reset()
        self.steps = 0

    def measurement(self, obs: np.ndarray, info: Mapping[str, Any] | None = None
                    ) -> dict[str, float]:
        """The measurement mapping (SI) rebuilt from one observation."""
        o = np.asarray(obs, dtype=float).reshape(-1)
        rs, ws = self.reference_scale, self.speed_scale
        t = float(info["time"]) if info is not None and "time" in info else self.steps * self.dt
        return {
            "time": t,
            "output_angle": o[0] * rs,
            "motor_angle": o[1] * rs * self.ratio,
            "motor_velocity": o[4] * ws,
            "output_velocity": o[5] * ws / self.ratio,
            "output_torque": o[6] * self.torque_scale,
            "motor_current": o[7] * self.current_limit,
            "reference": o[8] * rs,
        }

    def __call__(self, obs: np.ndarray, info: Mapping[str, Any] | None = None) -> np.ndarray:
        """Action (shape (1,), float32) for one observation."""
        m = self.measurement(obs, info)
        current = float(self.controller(m["time"], m))
        self.steps += 1
        if not math.isfinite(current):
            raise ValueError(f"controller returned {current!r} at t = {m['time']:.6g} s")
        a = np.clip(current / self.current_limit, -1.0, 1.0)
        return np.array([a], dtype=np.float32)

    def predict(self, obs: np.ndarray, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        """Stable-Baselines3-style ``predict`` (single env, state ignored)."""
        if episode_start is not None and bool(np.any(episode_start)):
            self.reset()
        return self(obs), None
