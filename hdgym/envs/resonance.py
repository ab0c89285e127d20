"""``HarmonicDriveResonance-v0``: run a joint up through its resonance trap."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

from hdgym.envs.common import HarmonicDriveEnv, resolve_params
from hdgym.envs.tasks import ResonanceTask
from hdgym.params import JointParams

#: A, the default ``current_limit``: ``None`` keeps the preset's amplifier (6 A on tuttle-joint1)
DEFAULT_CURRENT_LIMIT = None

#: A, the "trap-only" variant's amplifier (``current_limit=3.7``): full current stays trapped
TRAP_ONLY_CURRENT_LIMIT = 3.7


def resonance_params(preset: str | JointParams | None,
                     current_limit: float | None = DEFAULT_CURRENT_LIMIT) -> JointParams:
    """The task's drive: the preset with its amplifier current limit set to ``current_limit``.

    ``None`` keeps the preset's amplifier. The back-EMF (voltage) limit is
    the preset's either way. Raises ``ValueError`` unless the limit is a
    finite number > 0 A.
    """
    params = resolve_params(preset)
    if current_limit is None:
        return params
    try:
        limit = float(current_limit)
    except (TypeError, ValueError):
        raise ValueError(f"current_limit must be a number of A, got {current_limit!r}") from None
    if not (limit > 0 and math.isfinite(limit)):
        raise ValueError(f"current_limit must be > 0 A, got {current_limit!r}")
    return params.set("amplifier.current_limit", limit)


class HarmonicDriveResonanceEnv(HarmonicDriveEnv):
    """Bring the motor from rest to a target speed above a resonance trap.

    When an excitation order of the WG frequency (kinematic error, twice per
    turn) meets the joint's torsional natural frequency, the flexspline
    torque oscillates, load-dependent tooth friction drains the motor's
    power and the mean speed stays on a plateau (PHYSICS.md §3). On Tuttle's
    joint 1 (the default preset) the 2x-order trap sits near 8,000 deg/s of
    input speed; the target is drawn in 10,000-12,000 deg/s.

    The task (default, the preset's amplifier: 6 A on tuttle-joint1) is to
    get through the trap to the target while keeping the flexspline torque
    oscillation low (the reward penalizes it). Brute force crosses here:
    constant full current and a saturated PI speed loop reach the target,
    but with about twice the peak flexspline torque of a learned policy
    (PPO, ``agents/``: ~160 against ~330 N m mean peak over randomized
    episodes, ``results/rl/evaluation.md``). The back-EMF voltage limit of
    the preset is in force.

    ``current_limit=3.7`` is the *trap-only* variant: a smaller amplifier
    whose limit sits inside the velocity plateau (Tuttle's steps of
    2.8-4.0 A all settle in the trap; 4.4 A and up break out), so constant
    full current and a saturated speed controller stay below 9,000 deg/s in
    about 93 % of randomized 3 s episodes. As measured, nothing crosses
    there either: every shaped current tried (2x-order ripple locked to the
    WG angle, active damping of the twist from the torque sensor or the
    true states, pulses, ramps) lost more speed through the lower mean
    current than it saved in friction, and PPO converged to full current.
    The reason is physical: the motor's inertia reflected through the ratio
    (~5.7 kg m^2 against 1 kg m^2 at the output) leaves the current a share
    of ~0.15 of its torque on the torsional mode, ~5 N m at 3.7 A, against
    ~16-23 N m of kinematic-error forcing. Use it to show a trap, not as a
    solvable benchmark.

    ## Action space

    ``Box(-1, 1, (1,), float32)``: current command / ``I_max`` (the
    amplifier's limit: the preset's, or ``current_limit``). Values
    outside [-1, 1] saturate like the amplifier's input clip; NaN or
    infinite actions raise ``ValueError``. Current and back-EMF limits and
    the current loop act inside the physics.

    ## Observation space

    ``Box(-10, 10, (10,), float32)``, measured and normalized, clipped:

    | # | observation | scale |
    |---|---|---|
    | 0 | motor velocity from encoder counts | / target speed |
    | 1 | output velocity from counts x ratio | / target speed |
    | 2, 3 | cos, sin of the motor (WG) encoder angle | 1 |
    | 4 | torque sensor (flexspline torque) | / ``K_t I_max ratio`` |
    | 5 | measured motor current | / ``I_max`` |
    | 6 | target speed | / no-load speed ``V/K_b`` |
    | 7 | torque sensor minus its running mean (oscillation) | / ``K_t I_max ratio`` |
    | 8 | previous action (clipped) | 1 |
    | 9 | time | / ``horizon`` |

    ``info`` holds the true states (``motor_angle``, ``motor_velocity``,
    ``output_angle``, ``output_velocity``, ``motor_current``,
    ``output_torque``), ``time``, ``target_speed`` (rad/s),
    ``torque_oscillation`` (N m, true) and ``diverged``.

    ## Reward

    ``1 - min(|w_target - w_motor| / w_target, 2)
    - oscillation_weight * min(((T_k - mean T_k) / (K_t I_max ratio))^2, 4)``
    (true motor speed and flexspline torque; the mean is a first-order
    running mean with ``torque_time_constant``): 0 at rest, 1 at the target
    without vibration; minus ``safety_penalty`` on a safety termination.

    ## Starting state

    At rest, spring relaxed, WG angle uniform in [0, 2 pi) (friction and
    kinematic error vary with it, which makes the trap's exit erratic);
    target speed uniform in ``target_speed``.

    ## Episode end

    * Truncation at 2000 steps (2 s at 1 ms).
    * Termination: ``|flexspline torque| > torque_limit`` (default
      8 ``K_t I_max ratio``: 417 N m with the preset's 6 A, where a
      full-current run-up on tuttle-joint1 peaks at 330-380 N m; 257 N m
      with ``current_limit=3.7``),
      ``|motor speed| > speed_limit`` (default
      1.5 ``V/K_b``) or a diverging simulation.

    ## Arguments

    ``preset``, ``without``, ``ctrl_dt``, ``n_substeps``, ``sensors``,
    ``randomize``, ``horizon``, ``torque_limit``, ``speed_limit``,
    ``safety_penalty``, ``load_torque``, ``render_mode`` as in
    :class:`~hdgym.envs.joint.HarmonicDriveJointEnv`, and

    * ``target_speed``: motor speed, rad/s, a number or ``(low, high)``
      (default ``(radians(10000), radians(12000))``);
    * ``oscillation_weight`` (1.0), ``torque_time_constant`` (0.05 s);
    * ``current_limit``: A, replaces the preset's ``amplifier.current_limit``
      (default ``None``: the preset's amplifier, 6 A on tuttle-joint1;
      :data:`TRAP_ONLY_CURRENT_LIMIT` = 3.7 A is the trap-only variant);
      must be > 0. It also sets ``I_max`` in the action and observation
      scales and the default ``torque_limit``.
    """

    def __init__(self, preset: str | JointParams | None = None, without: Iterable[str] = (),
                 ctrl_dt: float | None = None, n_substeps: int | None = None,
                 sensors: Mapping[str, Any] | None = None,
                 randomize: Mapping[str, float] | None = None,
                 target_speed: float | tuple[float, float] = (
                     math.radians(10_000.0), math.radians(12_000.0)),
                 oscillation_weight: float = 1.0, torque_time_constant: float = 0.05,
                 horizon: float = 2.0, torque_limit: float | None = None,
                 speed_limit: float | None = None, safety_penalty: float = 100.0,
                 load_torque: float = 0.0, current_limit: float | None = DEFAULT_CURRENT_LIMIT,
                 render_mode: str | None = None) -> None:
        task = ResonanceTask(target_speed, oscillation_weight, torque_time_constant)
        params = resonance_params(preset, current_limit)
        super().__init__(task, render_mode, preset=params, without=without, ctrl_dt=ctrl_dt,
                         n_substeps=n_substeps, sensors=sensors, randomize=randomize,
                         horizon=horizon, torque_limit=torque_limit, speed_limit=speed_limit,
                         safety_penalty=safety_penalty, load_torque=load_torque)
