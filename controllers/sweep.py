"""``hdgym sweep`` scenarios ``controllers:NAME``: one controller config per run.

Each function runs ONE ``[[controllers]]`` config of a sweep spec on the
given, possibly randomized, drive. The controller is designed on the
*nominal* drive (the preset as the datasheet gives it, passed as
``nominal``): PID, KE model, DOB model; the randomized drive only runs it.
The settings, runs and metrics are the benchmark's
(:mod:`controllers.experiments`).

hdgym finds this module through the entry point ``controllers =
"controllers.sweep"`` of the group ``hdgym.sweep_scenarios`` (see
:mod:`hdgym.plugins`); importing it registers :data:`SCENARIOS` with
:func:`hdgym.sweep.scenarios.register_controller_scenario`.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from controllers import scenarios as S
from controllers.experiments import (
    KINDS,
    PRIMARY,
    TrackingDesign,
    controller_for,
    load_profile,
    load_step_metrics,
    load_step_peak,
    load_step_run,
    motor_held,
    point_to_point_metrics,
    point_to_point_run,
    settings,
    tracking_design,
    tracking_window,
)
from hdgym.params import JointParams, preset
from hdgym.sweep.scenarios import register_controller_scenario

#: keys of a controller config; numbers must be > 0
CONTROLLER_KEYS = {"name": str, "kind": str, "dob_bandwidth_hz": float, "rc_gain": float}
_ARCSEC = 180 / math.pi * 3600


class ControllerConfigError(ValueError):
    """A bad controller config; ``key`` names the offending key."""

    def __init__(self, msg: str, key: str | None = None):
        super().__init__(msg)
        self.key = key


def check_controller(config: Mapping[str, Any]) -> None:
    """Raise ValueError (:class:`ControllerConfigError`) for a bad controller config.

    Keys: ``name``, ``kind`` (one of :data:`KINDS`, default ``"pid"``),
    ``dob_bandwidth_hz`` (Q-filter bandwidth of ``pid+dob``; default 0.6 x
    the nominal resonance), ``rc_gain`` (learning gain of ``pid+repetitive``;
    default the benchmark's).
    """
    for key, value in config.items():
        if key not in CONTROLLER_KEYS:
            raise ControllerConfigError(
                f"unknown key {key!r}; known: {', '.join(sorted(CONTROLLER_KEYS))}", key)
        if CONTROLLER_KEYS[key] is float and not (
                isinstance(value, (int, float)) and not isinstance(value, bool)
                and math.isfinite(value) and value > 0):
            raise ControllerConfigError(f"{key} must be a number > 0, got {value!r}", key)
        if CONTROLLER_KEYS[key] is str and not isinstance(value, str):
            raise ControllerConfigError(f"{key} must be a string, got {value!r}", key)
    kind = config.get("kind", "pid")
    if kind not in KINDS:
        raise ControllerConfigError(f"kind must be one of {', '.join(KINDS)}, got {kind!r}",
                                    "kind" if "kind" in config else "name")


def _nominal_of(params: JointParams, nominal: JointParams | None) -> JointParams:
    return nominal if nominal is not None else preset(params.name)


@functools.lru_cache(maxsize=8)
def _pid(nominal: JointParams) -> Any:
    return S.motor_pid(nominal)[0]


@functools.lru_cache(maxsize=8)
def _tracking_design(nominal: JointParams, quick: bool, wg_rev_s: float) -> TrackingDesign:
    return tracking_design(nominal, settings(quick), wg_rev_s)


def _controller(config: Mapping[str, Any], scenario: str, nominal: JointParams,
                cfg: dict[str, float], design: TrackingDesign | None = None) -> Any | None:
    """The config's controller designed on ``nominal``; None if the kind sits this one out."""
    check_controller(config)
    kind = str(config.get("kind", "pid"))
    if scenario not in KINDS[kind]:
        return None
    pid = design.pid if design is not None else _pid(nominal)
    return controller_for(kind, nominal, pid, cfg, tracking=design,
                          dob_bandwidth_hz=config.get("dob_bandwidth_hz"),
                          rc_gain=config.get("rc_gain"))


@functools.lru_cache(maxsize=64)
def _pid_tracking_rms(params: JointParams, nominal: JointParams, quick: bool, wg_rev_s: float,
                      seed: int) -> float:
    cfg = settings(quick)
    d = _tracking_design(nominal, quick, wg_rev_s)
    run = S.closed_loop(params, d.pid, cfg["track_duration"], d.reference, seed=seed)
    return S.rms(run.error[tracking_window(run, cfg)])


def sweep_tracking(params: JointParams, controller: Mapping[str, Any], seed: int = 0,
                   quick: bool = False, nominal: JointParams | None = None,
                   wg_rev_s: float = 0.0) -> dict[str, float]:
    """Slow constant-speed tracking (benchmark 1): ``rms_error_arcsec``, ``max_error_arcsec``
    of the true output error from ``eval_start`` s to the end of the run, ``reduction_pct``
    of the RMS against the PID alone on the same drive and seed.

    ``wg_rev_s`` (WG rev/s; default the benchmark's plotted speed per joint,
    :data:`PRIMARY`). PID, KE model (identified from a separate PID record)
    and learnt orders come from the nominal drive; kinds ``pid``, ``pid+ke``,
    ``pid+ke-shift``, ``pid+repetitive``, ``pid+dob``.
    """
    nominal = _nominal_of(params, nominal)
    speed = float(wg_rev_s) or PRIMARY.get(nominal.name, 1.0)
    cfg = settings(quick)
    design = _tracking_design(nominal, quick, speed)
    ctl = _controller(controller, "tracking", nominal, cfg, design)
    run = S.closed_loop(params, ctl, cfg["track_duration"], design.reference, seed=seed)
    e = run.error[tracking_window(run, cfg)]
    rms = S.rms(e)
    base = rms if ctl is design.pid else _pid_tracking_rms(params, nominal, quick, speed, seed)
    return {"rms_error_arcsec": rms * _ARCSEC,
            "max_error_arcsec": float(np.abs(e).max()) * _ARCSEC,
            "reduction_pct": 100 * (1 - rms / base)}


@functools.lru_cache(maxsize=64)
def _pid_load_peak(params: JointParams, nominal: JointParams, quick: bool, seed: int) -> float:
    cfg = settings(quick)
    t, load, _ = load_profile(nominal, cfg)
    return load_step_peak(load_step_run(params, _pid(nominal), cfg, load, seed), t, cfg)


def sweep_load_step(params: JointParams, controller: Mapping[str, Any], seed: int = 0,
                    quick: bool = False, nominal: JointParams | None = None
                    ) -> dict[str, float]:
    """Load-torque step while holding position (benchmark 2): ``peak_deviation_arcsec``,
    ``recovery_s`` (until the deviation stays within 10 % of the PID's peak on the same drive
    of the drive's wind-up with the motor held at its setpoint; inf: not within the run),
    ``reduction_pct`` of the peak against the PID alone on the same drive and seed,
    ``peak_current_A``, ``chatter_A`` (RMS change of the current command per sample).

    The step (40 % of the nominal peak motor torque x ratio) and the
    controller come from the nominal drive; kinds ``pid``, ``pid+dob`` (other
    kinds return no metrics).
    """
    nominal = _nominal_of(params, nominal)
    cfg = settings(quick)
    ctl = _controller(controller, "load_step", nominal, cfg)
    if ctl is None:
        return {}
    t, load, _ = load_profile(nominal, cfg)
    run = load_step_run(params, ctl, cfg, load, seed)
    base = _pid_load_peak(params, nominal, quick, seed)
    _, windup = motor_held(params, cfg, load)
    m = load_step_metrics(run, t, nominal.integration.ctrl_dt, cfg, 0.1 * base, windup)
    return {"peak_deviation_arcsec": m["peak"] * _ARCSEC, "recovery_s": m["recovery"],
            "reduction_pct": 100 * (1 - m["peak"] / base),
            "peak_current_A": m["peak_current"], "chatter_A": m["chatter"]}


def sweep_point_to_point(params: JointParams, controller: Mapping[str, Any], seed: int = 0,
                         quick: bool = False, nominal: JointParams | None = None
                         ) -> dict[str, float]:
    """Minimum-jerk move of 0.5 output rad in 1 s (benchmark 3): ``overshoot_pct``,
    ``settling_s`` (to ±1 mrad after the reference move ends; inf, left out of the
    statistics: never settles in the run), ``peak_current_A``, ``final_error_arcsec``.

    Controller designed on the nominal drive; kinds ``pid``, ``pid+dob``
    (other kinds return no metrics).
    """
    nominal = _nominal_of(params, nominal)
    cfg = settings(quick)
    ctl = _controller(controller, "point_to_point", nominal, cfg)
    if ctl is None:
        return {}
    m = point_to_point_metrics(point_to_point_run(params, ctl, cfg, seed))
    return {"overshoot_pct": m["overshoot_pct"], "settling_s": m["settling_time"],
            "peak_current_A": m["peak_current"],
            "final_error_arcsec": abs(m["final_error"]) * _ARCSEC}


#: ``hdgym sweep`` scenarios ``controllers:NAME`` (registered below)
SCENARIOS: dict[str, Callable[..., dict[str, float]]] = {
    "tracking": sweep_tracking,
    "load_step": sweep_load_step,
    "point_to_point": sweep_point_to_point,
}

for _name, _fn in SCENARIOS.items():
    register_controller_scenario(f"controllers:{_name}", _fn, check_controller)
