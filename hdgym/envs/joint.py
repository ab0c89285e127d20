"""``HarmonicDriveJoint-v0``: output position tracking on a harmonic-drive joint."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from hdgym.envs.common import HarmonicDriveEnv
from hdgym.envs.tasks import TrackingTask
from hdgym.params import JointParams


class HarmonicDriveJointEnv(HarmonicDriveEnv):
    """Make the output of a harmonic-drive joint follow a position reference.

    A motor drives the wave generator of a harmonic drive (default: Tuttle's
    joint 1, preset ``tuttle-joint1``); the output carries a load. The agent
    commands motor current and sees what the hardware measures. Between the
    two sit the effects that make precise tracking hard: kinematic error
    (twice per WG turn), a compliant, hysteretic flexspline, friction that
    sticks, depends on position and on the transmitted load, and an
    amplifier with current and back-EMF limits.

    ## Action space

    ``Box(-1, 1, (1,), float32)``: the current command as a fraction of the
    amplifier's current limit ``I_max`` (so ``1`` asks for full current).
    Values outside [-1, 1] are accepted and saturate exactly like the
    amplifier's input clip; NaN or infinite actions raise ``ValueError``.
    The amplifier's back-EMF voltage limit and current loop act inside the
    physics at every substep.

    ## Observation space

    ``Box(-10, 10, (12,), float32)``, measured (quantized encoders, velocity
    from encoder counts, torque sensor and current with optional noise and
    a one-sample delay), normalized and clipped to the box:

    | # | observation | scale |
    |---|---|---|
    | 0 | output encoder angle | / ``reference_scale`` |
    | 1 | motor encoder angle / ratio | / ``reference_scale`` |
    | 2, 3 | cos, sin of the motor (WG) encoder angle | 1 |
    | 4 | motor velocity from counts | / no-load speed ``V/K_b`` |
    | 5 | output velocity from counts | / (``V/K_b`` / ratio) |
    | 6 | torque sensor (flexspline torque) | / ``K_t I_max ratio`` |
    | 7 | measured motor current | / ``I_max`` |
    | 8 | reference | / ``reference_scale`` |
    | 9 | reference velocity | / (``V/K_b`` / ratio) |
    | 10 | reference - output encoder angle | / ``error_scale`` |
    | 11 | previous action (clipped) | 1 |

    True states go in ``info``: ``motor_angle``, ``motor_velocity``,
    ``output_angle``, ``output_velocity``, ``motor_current``,
    ``output_torque`` (SI), ``time`` (s), ``reference``, ``tracking_error``
    (output rad, true) and ``diverged``.

    ## Reward

    ``1 / (1 + |e| / error_scale) - current_weight * min((i / I_max)^2, 4)``
    with ``e`` the true output tracking error, so 1 per step for perfect
    tracking at no current; minus ``safety_penalty`` on a safety termination.

    ## Starting state

    At rest with the spring relaxed, the WG angle drawn uniformly in
    [0, 2 pi) (the phase of the kinematic error). Randomized parameters and
    the reference are drawn per episode. References start at the initial
    output angle: a staircase of three random levels, a sine (0.2-2 Hz,
    peak speed capped), a slow constant speed (0.005-0.05 rad/s at the
    output, where kinematic error dominates) or a minimum-jerk
    point-to-point move.

    ## Episode end

    * Truncation at 2000 steps (2 s at the default 1 ms; ``max_episode_steps``
      of the registration).
    * Termination on a safety limit: ``|flexspline torque| > torque_limit``
      (default 8 ``K_t I_max ratio``; a full-current run up through the
      resonance on tuttle-joint1 peaks at about 85 % of it), ``|motor speed| > speed_limit``
      (default 1.5 ``V/K_b``), or a diverging simulation. Observations and
      ``info`` stay finite even then.

    ## Arguments

    * ``preset``: preset name (default ``"tuttle-joint1"``) or a JointParams.
    * ``without``: effect names to switch off (``hdgym.effects.EFFECTS``);
      unknown names raise ``ValueError``.
    * ``ctrl_dt`` (s), ``n_substeps``: control period and physics substeps
      (default: the preset's ``[integration]``).
    * ``sensors``: overrides of the preset's ``Sensors`` fields, e.g.
      ``{"torque_noise": 0.5, "current_noise": 0.02, "delay": 1,
      "output_counts": 80000}``.
    * ``randomize``: relative spread per dotted parameter path, e.g.
      ``{"compliance.stiffness": 0.1, "friction.output.coulomb": 0.3}``;
      each value is scaled by ``1 + spread * U(-1, 1)`` per episode.
    * ``reference``: ``"mixed"`` or one/several of ``"step"``, ``"sine"``,
      ``"constant_speed"``, ``"point_to_point"``.
    * ``reference_scale`` (0.5 rad), ``error_scale`` (1e-3 rad),
      ``current_weight`` (0.05), ``horizon`` (2 s, timing of references),
      ``torque_limit`` (N m), ``speed_limit`` (rad/s), ``safety_penalty``
      (100), ``load_torque`` (N m, constant, opposing positive motion),
      ``render_mode`` (``"rgb_array"`` or None).

    Seeding: ``reset(seed=s)`` seeds the env's generator; env ``i`` of the
    vector env (``gym.make_vec``) seeded with ``s`` behaves exactly like a
    single env reset with ``seed=s + i``.
    """

    def __init__(self, preset: str | JointParams | None = None, without: Iterable[str] = (),
                 ctrl_dt: float | None = None, n_substeps: int | None = None,
                 sensors: Mapping[str, Any] | None = None,
                 randomize: Mapping[str, float] | None = None,
                 reference: str | Sequence[str] = "mixed", reference_scale: float = 0.5,
                 error_scale: float = 1e-3, current_weight: float = 0.05, horizon: float = 2.0,
                 torque_limit: float | None = None, speed_limit: float | None = None,
                 safety_penalty: float = 100.0, load_torque: float = 0.0,
                 render_mode: str | None = None) -> None:
        task = TrackingTask(reference, reference_scale, error_scale, current_weight)
        super().__init__(task, render_mode, preset=preset, without=without, ctrl_dt=ctrl_dt,
                         n_substeps=n_substeps, sensors=sensors, randomize=randomize,
                         horizon=horizon, torque_limit=torque_limit, speed_limit=speed_limit,
                         safety_penalty=safety_penalty, load_torque=load_torque)
