"""Controller benchmark: ``hdgym controllers [--quick]`` → ``results/controllers.md``.

On ``tuttle-joint1`` and ``tuttle-joint3`` with every effect on, amplifier
limits and quantized encoders (``Simulator(sensors=True)``):

1. slow constant-speed output tracking (kinematic error dominates): PID
   alone, PID + kinematic-error feedforward identified from a separate
   record, PID + Fourier repetitive control after convergence; then the
   learnt repetitive series on a speed sweep (valid while the speed changes);
2. a load-torque step: PID alone against PID + disturbance observer;
3. a point-to-point move: overshoot, settling time, peak current;
4. the linear two-inertia model against the simulated small-signal response.

Errors are computed on the *true* output angle (re-simulated from the
recorded current; see :mod:`controllers.scenarios`); the controllers only
ever see the sensors. The PID is designed with python-control
(:func:`controllers.scenarios.motor_pid`), the same for every row.

:data:`SCENARIOS` runs the same scenarios one controller config at a time
for ``hdgym sweep`` (``controllers:tracking``, ``controllers:load_step``,
``controllers:point_to_point``; spec ``hdgym/sweep/specs/controllers.toml``):
designed on the nominal drive, run on a randomized one.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from controllers import scenarios as S
from controllers import tuning
from controllers.dob import DisturbanceObserver
from controllers.ke_feedforward import KEFeedforward, KEModel, identify_ke
from controllers.repetitive import RepetitiveController
from hdgym.params import JointParams, preset

JOINTS = ("tuttle-joint1", "tuttle-joint3")
#: WG speeds of the slow constant-speed runs, rev/s; both are reported
SPEEDS = (1.0, 1.5)
#: the speed whose runs are plotted and swept, per joint: the one where the
#: PID's error is dominated by the kinematic error (joint 1 at 1 rev/s moves
#: its output at ~2 x the Stribeck speed and stick-slip dominates)
PRIMARY = {"tuttle-joint1": 1.5, "tuttle-joint3": 1.0}
#: targets stated in the brief
KE_TARGET = 70.0
RC_TARGET = 90.0
DOB_TARGET = 50.0


def settings(quick: bool) -> dict[str, float]:
    """Durations (s) and parameters of each scenario."""
    return {
        "identify_duration": 90.0 if quick else 150.0,
        "track_duration": 40.0 if quick else 80.0,
        "eval_start": 10.0,
        "ramp_time": 2.0,
        "rc_gain": 0.5,
        "rc_start": 5.0,
        "sweep_duration": 30.0 if quick else 40.0,
        "load_duration": 4.0,
        "load_step_time": 1.0,
        "p2p_duration": 3.0,
        "bode_duration": 40.0 if quick else 120.0,
    }


def dob_for(p: JointParams, controller: Any, bandwidth_hz: float | None = None
            ) -> DisturbanceObserver:
    """A DOB with the datasheet (nominal) rigid-body model of ``p``; Q at 0.6 f_res."""
    jn = p.motor.inertia + p.load.inertia / p.ratio ** 2
    bn = p.friction.input.viscous + p.friction.output.viscous / p.ratio ** 2
    bw = 0.6 * tuning.resonance_hz(p) if bandwidth_hz is None else bandwidth_hz
    return DisturbanceObserver(controller, jn, p.motor.torque_constant, bw,
                               p.integration.ctrl_dt, damping=bn,
                               current_limit=p.amplifier.current_limit)


# ------------------------------------------------------------------ scenarios


def chatter(run: S.Run) -> float:
    """RMS sample-to-sample change of the current command, A."""
    return float(np.sqrt(np.mean(np.diff(run.record.columns["current_command"]) ** 2)))


@dataclass
class TrackingDesign:
    """What the slow-tracking controllers are built from, designed on one drive."""

    wg_rev_s: float
    output_speed: float
    reference: Callable[[float], float]
    pid: Any
    design: Any
    model: KEModel
    #: orders the KE model is fitted at / the repetitive controller learns at
    fit_orders: tuple[float, ...]
    orders: tuple[float, ...]


def tracking_design(p: JointParams, cfg: dict[str, float], wg_rev_s: float) -> TrackingDesign:
    """PID design and KE identification for constant-speed tracking at ``wg_rev_s``.

    The KE model is fitted at the WG orders 1, 2, 4 and the split lines of
    the non-grounded spline (:func:`controllers.scenarios.ke_orders`) from a
    separate (longer) PID record; the repetitive controller learns at the
    orders whose identified amplitude is at least 10 % of the largest.
    """
    w_out = wg_rev_s * 2 * math.pi / p.ratio
    ref = S.ramp(w_out, ramp_time=cfg["ramp_time"])
    fit_orders = S.ke_orders(p.ratio, p.transmission.grounded)
    pid, design = S.motor_pid(p)

    # identification record: PID alone, a separate (longer) run
    ident = S.closed_loop(p, pid, cfg["identify_duration"], ref, seed=1)
    model = identify_ke(ident.record, fit_orders, settle=cfg["ramp_time"] + 2.0)
    amps = model.amplitudes()
    orders = tuple(o for o, a in amps.items() if a >= 0.1 * max(amps.values()))
    return TrackingDesign(wg_rev_s, w_out, ref, pid, design, model, fit_orders, orders)


def controller_for(kind: str, p: JointParams, pid: Any, cfg: dict[str, float], *,
                   tracking: TrackingDesign | None = None,
                   dob_bandwidth_hz: float | None = None, rc_gain: float | None = None) -> Any:
    """A fresh controller of ``kind`` (see :data:`KINDS`) around ``pid``, designed on ``p``.

    ``pid+ke-shift``, ``pid+ke`` and ``pid+repetitive`` need the KE model and
    orders of a :class:`TrackingDesign`.
    """
    if kind == "pid":
        return pid
    if kind == "pid+dob":
        return dob_for(p, pid, dob_bandwidth_hz)
    if kind not in KINDS:
        raise ValueError(f"unknown controller kind {kind!r}; known: {', '.join(KINDS)}")
    if tracking is None:
        raise ValueError(f"controller kind {kind!r} needs a tracking design (KE model)")
    if kind == "pid+ke-shift":
        return KEFeedforward(pid, tracking.model, p.ratio)
    if kind == "pid+ke":
        return KEFeedforward(pid, tracking.model, p.ratio, offset=True,
                             torque_constant=p.motor.torque_constant,
                             load_inertia=p.load.inertia / p.ratio ** 2,
                             dt=p.integration.ctrl_dt)
    return RepetitiveController(pid, p.ratio, tracking.orders,
                                cfg["rc_gain"] if rc_gain is None else rc_gain,
                                start=cfg["rc_start"],
                                output_offset=S.half_count(p.sensors.output_counts))


def tracking_window(run: S.Run, cfg: dict[str, float]) -> np.ndarray:
    """Samples of a tracking run that are scored (from ``eval_start`` to the end)."""
    return run.time >= cfg["eval_start"]


#: the tracking benchmark's rows and the controller kind of each
TRACKING_ROWS = {"PID": "pid", "PID + KE ref. shift only": "pid+ke-shift",
                 "PID + KE feedforward": "pid+ke", "PID + repetitive": "pid+repetitive"}


def tracking(p: JointParams, cfg: dict[str, float], wg_rev_s: float,
             sweep_too: bool = True) -> dict[str, Any]:
    """Slow constant-speed tracking: PID, PID + KE feedforward, PID + repetitive.

    Designed by :func:`tracking_design` on ``p``; the controllers are
    :func:`controller_for` of each kind in :data:`TRACKING_ROWS`.
    """
    d = tracking_design(p, cfg, wg_rev_s)
    pid, design, model, orders, ref = d.pid, d.design, d.model, d.orders, d.reference
    w_out, fit_orders = d.output_speed, d.fit_orders

    dur = cfg["track_duration"]
    ctls = {k: controller_for(kind, p, pid, cfg, tracking=d) for k, kind in TRACKING_ROWS.items()}
    rc = ctls["PID + repetitive"]
    runs: dict[str, S.Run] = {k: S.closed_loop(p, c, dur, ref) for k, c in ctls.items()}

    win = tracking_window(runs["PID"], cfg)
    t = runs["PID"].time
    rms = {k: S.rms(r.error[win]) for k, r in runs.items()}
    base = rms["PID"]
    reduction = {k: 100 * (1 - v / base) for k, v in rms.items()}

    # stability condition of the learning law on the linear closed loop
    closed = tuning.closed_loop(p, design, "motor", delay=p.integration.ctrl_dt)
    contraction = rc.contraction(closed, [wg_rev_s * 2 * math.pi])

    # the learnt series on a speed sweep (kept across runs; indexed by angle)
    v0, v1 = 0.67 * w_out, 1.33 * w_out
    sweep_rms: dict[str, float] = {}
    sweep_runs: dict[str, S.Run] = {}
    if sweep_too:
        sweep = S.speed_sweep(v0, v1, start=5.0, sweep_time=cfg["sweep_duration"] - 10.0)
        sweep_runs = {"PID": S.closed_loop(p, pid, cfg["sweep_duration"], sweep),
                      "PID + repetitive (learnt)": S.closed_loop(p, rc, cfg["sweep_duration"],
                                                                 sweep)}
        ts = sweep_runs["PID"].time
        sw = (ts >= 5.0) & (ts <= cfg["sweep_duration"] - 5.0)
        sweep_rms = {k: S.rms(r.error[sw]) for k, r in sweep_runs.items()}

    # convergence of the repetitive controller: RMS per WG-order period block
    block = 2.0
    edges = np.arange(0.0, dur + 1e-9, block)
    conv = [(float(a), S.rms(runs["PID + repetitive"].error[(t >= a) & (t < a + block)]),
             S.rms(runs["PID"].error[(t >= a) & (t < a + block)])) for a in edges[:-1]]
    return {
        "wg_rev_s": wg_rev_s, "output_speed": w_out, "orders": orders,
        "fit_orders": fit_orders, "model": model, "design": design,
        "rms": rms, "reduction": reduction, "runs": runs, "convergence": conv,
        "contraction": contraction, "sweep": (v0, v1), "sweep_rms": sweep_rms,
        "sweep_runs": sweep_runs,
        "window": cfg["eval_start"],
        "measured_rms": {k: S.rms(r.measured_error[win]) for k, r in runs.items()},
    }


def load_profile(p: JointParams, cfg: dict[str, float]) -> tuple[np.ndarray, np.ndarray, float]:
    """Time, output load torque (a step of 40 % of the peak motor torque x ratio) and step, N m."""
    step = 0.4 * p.motor.torque_constant * p.amplifier.current_limit * p.ratio
    dt = p.integration.ctrl_dt
    t = np.arange(int(round(cfg["load_duration"] / dt))) * dt
    return t, np.where(t >= cfg["load_step_time"], step, 0.0), step


def load_step_run(p: JointParams, controller: Any, cfg: dict[str, float], load: np.ndarray,
                  seed: int = 0) -> S.Run:
    """Hold position on ``p`` while ``load`` acts on the output."""
    return S.closed_loop(p, controller, cfg["load_duration"], lambda _t: 0.0, load_torque=load,
                         seed=seed)


def load_step_peak(run: S.Run, t: np.ndarray, cfg: dict[str, float]) -> float:
    """Peak |output deviation| after the step, output rad (``t`` of :func:`load_profile`)."""
    return float(np.abs(run.error[t >= cfg["load_step_time"]]).max())


def load_step_metrics(run: S.Run, t: np.ndarray, dt: float, cfg: dict[str, float],
                      band: float) -> dict[str, float]:
    """``peak`` |deviation|, ``recovery`` (until the deviation stays within ``band`` of its
    final value, the mean of the last 0.2 s), ``final``, ``peak_current``, ``chatter`` of a
    load-step run (rad, s, rad, A, A); ``t`` of :func:`load_profile`, ``dt`` the control
    period."""
    dev = -run.error
    final = float(dev[-int(0.2 / dt):].mean())
    m = S.deviation_metrics(t, dev - final, cfg["load_step_time"], band)
    m["peak"] = float(np.abs(dev[t >= cfg["load_step_time"]]).max())
    m["final"] = final
    m["peak_current"] = float(np.abs(run.record.columns["current_command"]).max())
    m["chatter"] = chatter(run)
    return m


def load_step(p: JointParams, cfg: dict[str, float]) -> dict[str, Any]:
    """Holding position while a load torque steps on: PID alone vs PID + DOB."""
    t, load, step = load_profile(p, cfg)
    pid, _ = S.motor_pid(p)
    dob = controller_for("pid+dob", p, pid, cfg)
    runs = {"PID": load_step_run(p, pid, cfg, load),
            "PID + DOB": load_step_run(p, dob, cfg, load)}
    peak_pid = load_step_peak(runs["PID"], t, cfg)
    band = 0.1 * peak_pid
    metrics = {k: load_step_metrics(r, t, p.integration.ctrl_dt, cfg, band)
               for k, r in runs.items()}
    # Q-filter bandwidth trade-off: rejection against current chatter
    fres = tuning.resonance_hz(p)
    q_sweep = []
    for frac in (0.3, 0.45, 0.6):
        r = load_step_run(p, dob_for(p, pid, frac * fres), cfg, load)
        peak = load_step_peak(r, t, cfg)
        q_sweep.append((frac * fres, 100 * (1 - peak / peak_pid), chatter(r)))
    return {"step": step, "band": band, "metrics": metrics, "runs": runs,
            "dob_bandwidth": dob.bandwidth_hz, "q_sweep": q_sweep,
            "reduction": 100 * (1 - metrics["PID + DOB"]["peak"] / metrics["PID"]["peak"])}


#: point-to-point move: distance (output rad), start (s), move time (s), settling band (rad)
P2P_MOVE = {"distance": 0.5, "start": 0.2, "move_time": 1.0, "band": 1e-3}


def point_to_point_run(p: JointParams, controller: Any, cfg: dict[str, float],
                       seed: int = 0) -> S.Run:
    """The minimum-jerk move of :data:`P2P_MOVE` on ``p``."""
    ref = S.min_jerk(P2P_MOVE["distance"], P2P_MOVE["start"], P2P_MOVE["move_time"])
    return S.closed_loop(p, controller, cfg["p2p_duration"], ref, seed=seed)


def point_to_point_metrics(run: S.Run) -> dict[str, float]:
    """``overshoot_pct``, ``settling_time`` (s after the reference move ends; inf: never
    settles in the run), ``peak_current`` (A), ``final_error`` (rad), ``chatter`` (A)."""
    dist, start, move = P2P_MOVE["distance"], P2P_MOVE["start"], P2P_MOVE["move_time"]
    m = S.step_metrics(run.time, run.output_angle, dist, start, P2P_MOVE["band"])
    m["settling_time"] -= move if math.isfinite(m["settling_time"]) else 0.0
    m["peak_current"] = float(np.abs(run.record.columns["current_command"]).max())
    m["final_error"] = float(run.error[-1])
    m["chatter"] = chatter(run)
    return m


def point_to_point(p: JointParams, cfg: dict[str, float]) -> dict[str, Any]:
    """Minimum-jerk move of 0.5 output rad in 1 s from rest."""
    pid, _ = S.motor_pid(p)
    runs = {"PID": point_to_point_run(p, pid, cfg),
            "PID + DOB": point_to_point_run(p, controller_for("pid+dob", p, pid, cfg), cfg)}
    metrics = {k: point_to_point_metrics(r) for k, r in runs.items()}
    return {"distance": P2P_MOVE["distance"], "move_time": P2P_MOVE["move_time"],
            "start": P2P_MOVE["start"], "band": P2P_MOVE["band"],
            "metrics": metrics, "runs": runs}


def bode(p: JointParams, cfg: dict[str, float]) -> dict[str, Any]:
    """Linear model against the simulated H1 response (non-linear effects off)."""
    lin = tuning.small_signal_joint(p)
    sys = tuning.linearize(lin)
    out = {}
    fr = tuning.resonance_hz(lin)
    fa = math.sqrt(tuning.stiffness(lin) / lin.load.inertia) / (2 * math.pi)
    fmax = 0.6 * min(fr, fa)
    for ch in ("motor_velocity", "output_torque"):
        f, h, coh = tuning.simulated_response(lin, ch, duration=cfg["bode_duration"])
        m = tuning.model_response(sys, ch, f, dt=lin.integration.ctrl_dt)
        k = (f >= 1.0) & (f <= fmax)
        db = 20 * np.log10(np.abs(h[k]) / np.abs(m[k]))
        deg = np.degrees(np.angle(h[k] / m[k]))
        out[ch] = {"f": f, "h": h, "model": m, "coherence": coh,
                   "max_db": float(np.abs(db).max()), "max_deg": float(np.abs(deg).max())}
    return {"channels": out, "fmax": fmax, "resonance_hz": fr, "antiresonance_hz": fa}


# ------------------------------------------------- one controller per run (sweeps)
#
# ``SCENARIOS`` is what ``hdgym sweep`` runs for ``controllers:NAME``
# (hdgym.sweep.scenarios): each function runs ONE controller config on the
# given, possibly randomized, drive. The controller is designed on the
# *nominal* drive (the preset as the datasheet gives it, passed as
# ``nominal``): PID, KE model, DOB model; the randomized drive only runs it.
# The settings, runs and metrics are the benchmark's above.

#: controller kinds and the benchmark scenarios each takes part in
KINDS: dict[str, tuple[str, ...]] = {
    "pid": ("tracking", "load_step", "point_to_point"),
    "pid+ke": ("tracking",),
    "pid+ke-shift": ("tracking",),
    "pid+repetitive": ("tracking",),
    "pid+dob": ("tracking", "load_step", "point_to_point"),
}
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
    of its final value; inf: not within the run), ``reduction_pct`` of the peak against the
    PID alone on the same drive and seed, ``peak_current_A``, ``chatter_A`` (RMS change of the
    current command per sample).

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
    m = load_step_metrics(run, t, nominal.integration.ctrl_dt, cfg, 0.1 * base)
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


#: ``hdgym sweep`` scenarios ``controllers:NAME``; see :mod:`hdgym.sweep.scenarios`
SCENARIOS: dict[str, Callable[..., dict[str, float]]] = {
    "tracking": sweep_tracking,
    "load_step": sweep_load_step,
    "point_to_point": sweep_point_to_point,
}


# ------------------------------------------------------------------ figures


def _save(fig: Any, figdir: Path, filename: str) -> str:
    """Write a figure into ``figdir``; return its path relative to the page."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(figdir / filename, dpi=110)
    plt.close(fig)
    return f"controllers/{filename}"


def _figures(name: str, res: dict[str, Any], figdir: Path) -> dict[str, str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figdir.mkdir(parents=True, exist_ok=True)
    files = {}
    deg = 180 / math.pi

    tr = res["tracking"][res["primary"]]
    fig, ax = plt.subplots(3, 1, figsize=(8, 9))
    for k, r in tr["runs"].items():
        t = r.time
        win = t >= t[-1] - 4.0
        ax[0].plot(t[win], r.error[win] * deg * 3600, label=k, lw=0.8)
    ax[0].set(xlabel="time (s)", ylabel="output error (arcsec)",
              title=f"{name}: {tr['wg_rev_s']} WG rev/s, last 4 s")
    ax[0].legend(fontsize=7)
    conv = np.array(tr["convergence"])
    ax[1].semilogy(conv[:, 0], conv[:, 2] * deg * 3600, "o-", label="PID")
    ax[1].semilogy(conv[:, 0], conv[:, 1] * deg * 3600, "o-", label="PID + repetitive")
    ax[1].set(xlabel="time (s)", ylabel="RMS error per 2 s (arcsec)",
              title="repetitive control convergence")
    ax[1].legend(fontsize=7)
    for k, r in tr["sweep_runs"].items():
        ax[2].plot(r.time, r.error * deg * 3600, label=k, lw=0.8)
    ax[2].set(xlabel="time (s)", ylabel="output error (arcsec)",
              title="speed sweep with the learnt series kept")
    ax[2].legend(fontsize=7)
    files["tracking"] = _save(fig, figdir, f"tracking_{name}.png")

    ls = res["load_step"]
    fig, ax = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for k, r in ls["runs"].items():
        ax[0].plot(r.time, -r.error * deg * 3600, label=k, lw=0.8)
        ax[1].plot(r.time, r.record.columns["current_command"], label=k, lw=0.8)
    ax[0].set(ylabel="output deviation (arcsec)", title=f"{name}: load step {ls['step']:.3g} N m")
    ax[1].set(xlabel="time (s)", ylabel="current command (A)")
    ax[0].legend(fontsize=7)
    files["load_step"] = _save(fig, figdir, f"load_step_{name}.png")

    pp = res["point_to_point"]
    fig, ax = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    for k, r in pp["runs"].items():
        ax[0].plot(r.time, r.output_angle * deg, label=k, lw=0.8)
        ax[1].plot(r.time, r.error * deg, label=k, lw=0.8)
        ax[2].plot(r.time, r.record.columns["current_command"], label=k, lw=0.8)
    r0 = next(iter(pp["runs"].values()))
    ax[0].plot(r0.time, r0.reference * deg, "k--", lw=0.8, label="reference")
    ax[0].set(ylabel="output angle (deg)", title=f"{name}: point-to-point move")
    ax[1].set(ylabel="error (deg)")
    ax[2].set(xlabel="time (s)", ylabel="current command (A)")
    ax[0].legend(fontsize=7)
    files["point_to_point"] = _save(fig, figdir, f"point_to_point_{name}.png")

    bd = res["bode"]
    fig, ax = plt.subplots(2, 2, figsize=(10, 6))
    for j, (ch, d) in enumerate(bd["channels"].items()):
        k = (d["f"] >= 0.5) & (d["f"] <= 200)
        ax[0, j].semilogx(d["f"][k], 20 * np.log10(np.abs(d["h"][k])), label="simulated (H1)")
        ax[0, j].semilogx(d["f"][k], 20 * np.log10(np.abs(d["model"][k])), "--",
                          label="linear model")
        ax[1, j].semilogx(d["f"][k], np.degrees(np.unwrap(np.angle(d["h"][k]))))
        ax[1, j].semilogx(d["f"][k], np.degrees(np.unwrap(np.angle(d["model"][k]))), "--")
        for a in ax[:, j]:
            a.axvline(bd["fmax"], color="grey", lw=0.6)
        ax[0, j].set(title=f"{name}: current → {ch}", ylabel="dB")
        ax[1, j].set(xlabel="Hz", ylabel="deg")
        ax[0, j].legend(fontsize=7)
    files["bode"] = _save(fig, figdir, f"bode_{name}.png")
    return files


# ------------------------------------------------------------------ report


def _verdict(value: float, target: float) -> str:
    return "met" if value >= target else "**not met**"


def _markdown(results: dict[str, Any], quick: bool, elapsed: float) -> str:
    as_ = 180 / math.pi * 3600
    cmd = "hdgym controllers --quick" if quick else "hdgym controllers"
    lines = [
        "# Controller benchmark",
        "",
        f"Regenerate with `{cmd}` (writes this page and `results/controllers/*.png`; "
        f"`hdgym controllers` runs longer records, `--quick` shorter ones). "
        f"Run time {elapsed:.0f} s.",
        "",
        "Every run uses the preset with all effects on, the amplifier limits and the "
        "quantized encoders (`Simulator(sensors=True)`); controllers only see the "
        "measurements. Errors are on the **true** output angle (re-simulated from the "
        "recorded current). The PID acts on the motor encoder (semi-closed loop) and is "
        "designed with python-control on the linearized joint "
        "(`controllers.tuning.design_pid`, 45° phase margin, crossover lowered until "
        "`controllers.tuning.loop_margins` also gives ≥ 6 dB gain margin across the "
        "resonance), with inertia feedforward of the nominal rigid-body inertia.",
        "",
        "## Targets",
        "",
        "| joint | WG speed | KE feedforward (≥ 70 % lower RMS) | repetitive (≥ 90 % lower) "
        "| DOB load step (≥ 50 % lower peak, faster recovery) |",
        "|---|---|---|---|---|",
    ]
    for name, res in results.items():
        ls = res["load_step"]
        faster = ls["metrics"]["PID + DOB"]["recovery"] < ls["metrics"]["PID"]["recovery"]
        dob = (f"{ls['reduction']:.0f} %, "
               f"{'faster' if faster else 'not faster'}: "
               f"{_verdict(ls['reduction'] if faster else -1.0, DOB_TARGET)}")
        for rev, t_ in res["tracking"].items():
            ke = t_["reduction"]["PID + KE feedforward"]
            rc = t_["reduction"]["PID + repetitive"]
            lines.append(f"| {name} | {rev} rev/s{' (plotted)' if rev == res['primary'] else ''}"
                         f" | {ke:.0f} %: {_verdict(ke, KE_TARGET)} | {rc:.0f} %: "
                         f"{_verdict(rc, RC_TARGET)} | {dob} |")
    lines += [
        "",
        "What limits the results (from the runs below and the diagnostics behind them):",
        "",
        "- tuttle-joint1 at 1 WG rev/s: the output moves at 2.2 °/s, about twice the "
        "preset's output Stribeck velocity (0.02 rad/s), and neither the feedforward nor "
        "the repetitive controller gets below about 21 arcsec; since the repetitive "
        "controller removes whatever is periodic in the WG angle at the learnt orders, "
        "the remainder is not, most likely friction-driven (stick-slip-like) motion. Both "
        "targets are **not met** there; at 1.5 rev/s both are met.",
        "- Shifting the motor reference alone (\"KE ref. shift only\") is not enough and "
        "on tuttle-joint3 makes things worse: the kinematic error also feeds the "
        "transmitted torque back to the motor (T_k θ_ke', PHYSICS.md §2.1), and the "
        "motor loop, whose bandwidth the lightly damped resonance limits, cannot follow "
        "the shifted reference without the torque and motor-only inertia terms.",
        "- The KE feedforward's wind-up term is a constant identified at one speed and "
        "load; the output friction ripple (once per output revolution) changes the "
        "wind-up along the run, which is the slowly drifting offset left in the "
        "feedforward trace. Feeding the torque sensor through the identified compliance "
        "instead was tried and made tracking worse (the correction changes the torque it "
        "is computed from).",
        "- After a load step the output keeps the flexspline wind-up (ΔT/k) that a "
        "motor-side loop cannot see; on tuttle-joint3 the PID alone also stays where "
        "static friction catches the output (recovery to its own final value is quick, "
        "but that final value is the peak deviation).",
        "",
    ]
    for name, res in results.items():
        ls, pp, bd = res["load_step"], res["point_to_point"], res["bode"]
        tr = res["tracking"][res["primary"]]
        d = tr["design"]
        cfg = res["cfg"]
        lines += [
            f"## {name}",
            "",
            f"PID: kp {d.kp:.4g} A/rad, ki {d.ki:.4g} A/(rad s), kd {d.kd:.4g} A s/rad, "
            f"derivative filter {d.tf * 1e3:.3g} ms"
            + (", notch at the resonance" if d.loop_filter is not None else "")
            + f"; crossover {d.crossover_hz:.3g} Hz, phase margin {d.phase_margin_deg:.1f}°, "
            f"gain margin {d.gain_margin_db:.1f} dB (linear torsional resonance "
            f"{tuning.resonance_hz(preset(name)):.1f} Hz with the stuck hysteresis stiffness).",
            "",
            "### Slow constant speed",
            "",
            f"RMS of the true output error from t = {tr['window']:.0f} s to the end of a "
            f"{tr['runs']['PID'].time[-1] + 0.001:.0f} s run (the repetitive controller has "
            "converged by then; see the figure). The KE model is identified "
            f"from a separate {cfg['identify_duration']:.0f} s PID record at the same speed "
            f"(`identify_ke`, orders {', '.join(f'{o:.4g}' for o in tr['fit_orders'])}); the "
            f"repetitive controller learns at the identified orders ≥ 10 % of the largest, "
            f"gain {cfg['rc_gain']} per WG revolution, from t = {cfg['rc_start']:.0f} s. "
            "\"KE ref. shift only\" moves the motor reference by ratio × θ_ke(θ_wg); "
            "\"KE feedforward\" also adds the identified mean wind-up (valid at that speed "
            "and load) and the current −T_k θ_ke'(θ_wg)/K_t that cancels the torque the "
            "kinematic error feeds back to the motor (T_k from the torque sensor). "
            "\"Encoder\" is the same error as the output encoder reports it (it floors to "
            "whole counts, so it reads up to one count low).",
            "",
            "| WG speed | output speed | controller | RMS error (arcsec) | RMS error (µrad) | "
            "reduction vs PID | encoder (arcsec) | target |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for rev, t_ in res["tracking"].items():
            for k, v in t_["rms"].items():
                red = t_["reduction"][k]
                target = ""
                if k == "PID + KE feedforward":
                    target = f"≥ {KE_TARGET:.0f} %: {_verdict(red, KE_TARGET)}"
                elif k == "PID + repetitive":
                    target = f"≥ {RC_TARGET:.0f} %: {_verdict(red, RC_TARGET)}"
                lines.append(
                    f"| {rev} rev/s | {t_['output_speed'] * 180 / math.pi:.3g} °/s | {k} | "
                    f"{v * as_:.2f} | {v * 1e6:.2f} | "
                    f"{'—' if k == 'PID' else f'{red:.0f} %'} | "
                    f"{t_['measured_rms'][k] * as_:.2f} | {target} |")
        lines += [""]
        for rev, t_ in res["tracking"].items():
            amps = t_["model"].amplitudes()
            lines += [
                f"At {rev} rev/s: identified KE amplitudes (arcsec) "
                + ", ".join(f"order {o:.4g}: {a * as_:.2f}" for o, a in amps.items())
                + f" (fit residual {t_['model'].residual_rms * as_:.2f} arcsec); learning "
                "stability |1 − L T(j n ω)| on the linear closed loop per learnt order: "
                + ", ".join(f"{o:.4g}: {c:.2f}" for o, c in zip(t_["orders"],
                                                                t_["contraction"][:, 0],
                                                                strict=True)) + ".",
                "",
            ]
        lines += [
            "The stated condition is |1 − L T(j n ω)| < 1 for every learnt order and speed "
            "(`controllers.repetitive`). The linear closed loop leaves out friction and "
            "hysteresis, which damp the real loop; a value ≥ 1 means the linear check cannot "
            "vouch for that order, not that the run diverged (the runs above show whether "
            "it converged).",
            "",
            f"Speed sweep at {res['primary']} rev/s nominal, "
            f"{tr['sweep'][0] * 180 / math.pi:.3g} → {tr['sweep'][1] * 180 / math.pi:.3g} °/s "
            "output, with the learnt series kept and learning on (indexed by the WG angle, "
            "so it needs no relearning when the speed changes): RMS error "
            + ", ".join(f"{k} {v * as_:.2f} arcsec" for k, v in tr["sweep_rms"].items())
            + ".",
            "",
            f"![tracking]({res['figures']['tracking']})",
            "",
            f"### Load-torque step ({ls['step']:.3g} N m at the output, holding position)",
            "",
            f"DOB: nominal rigid-body inertia and viscous friction from the datasheet "
            f"values, Q-filter (τs+1)⁻² at {ls['dob_bandwidth']:.3g} Hz, Tustin "
            f"(`control.sample_system`). Recovery: time until the output deviation stays "
            f"within ±{ls['band'] * as_:.1f} arcsec (10 % of the PID peak) of its final "
            "value (the mean of the last 0.2 s, mostly wind-up and friction hold).",
            "",
            "| controller | peak deviation (arcsec) | recovery (s) | deviation at end "
            "(arcsec) | peak current (A) | current chatter (A) |",
            "|---|---|---|---|---|---|",
        ]
        for k, m in ls["metrics"].items():
            lines.append(f"| {k} | {m['peak'] * as_:.1f} | {m['recovery']:.3f} | "
                         f"{m['final'] * as_:.1f} | {m['peak_current']:.3g} | "
                         f"{m['chatter']:.3g} |")
        lines += [
            "",
            "Current chatter is the RMS sample-to-sample change of the command. The "
            "Q-filter bandwidth trades rejection for chatter (same load step): "
            + "; ".join(f"{f:.3g} Hz: {red:.0f} % lower peak, chatter {c:.3g} A"
                        for f, red, c in ls["q_sweep"])
            + f". Meeting the {DOB_TARGET:.0f} % target: "
            + (", ".join(f"{f:.3g} Hz" for f, red, _ in ls["q_sweep"] if red >= DOB_TARGET)
               or "none")
            + ". With the DOB the current chatters more than with the PID alone (the "
            "observer also sees the torsional vibration and the encoder steps) and, while "
            "static friction holds the output, the loop hunts slowly (current traces).",
        ]
        faster = ls["metrics"]["PID + DOB"]["recovery"] < ls["metrics"]["PID"]["recovery"]
        lines += [
            "",
            f"Peak deviation {ls['reduction']:.0f} % lower with the DOB (target ≥ "
            f"{DOB_TARGET:.0f} %: {_verdict(ls['reduction'], DOB_TARGET)}); recovery "
            f"{'faster' if faster else '**not faster**'}. The deviation that remains is "
            "mostly the flexspline wind-up under the new load, which a motor-side loop "
            "cannot see.",
            "",
            f"![load step]({res['figures']['load_step']})",
            "",
            f"### Point-to-point ({pp['distance']} rad minimum-jerk move in "
            f"{pp['move_time']} s)",
            "",
            f"Settling time after the end of the reference move, to ±{pp['band'] * 1e3:.1f} "
            "mrad (true output).",
            "",
            "| controller | overshoot (%) | settling time (s) | peak current (A) | "
            "final error (arcsec) | current chatter (A) |",
            "|---|---|---|---|---|---|",
        ]
        for k, m in pp["metrics"].items():
            lines.append(f"| {k} | {m['overshoot_pct']:.2f} | {m['settling_time']:.3f} | "
                         f"{m['peak_current']:.3g} | {m['final_error'] * as_:.1f} | "
                         f"{m['chatter']:.3g} |")
        lines += [
            "",
            "Settling time inf: the output never stays inside the band (with the PID alone "
            "on tuttle-joint3 static friction stops it outside, and the weak integral "
            "action does not free it within the run). A negative value means it settled "
            "before the reference move ended.",
        ]
        lines += [
            "",
            f"![point to point]({res['figures']['point_to_point']})",
            "",
            "### Linear model against the simulated response",
            "",
            "`controllers.tuning.linearize` (two inertias, compliance slope, viscous "
            "terms, current loop; zero-order-hold sampled) against the H1 estimate from "
            "random current through the Simulator with Coulomb-type friction, hysteresis, "
            f"kinematic error and amplifier clipping off; 1 Hz to {bd['fmax']:.1f} Hz "
            f"(0.6 × min(resonance {bd['resonance_hz']:.1f} Hz, anti-resonance "
            f"{bd['antiresonance_hz']:.1f} Hz)).",
            "",
            "| channel | max magnitude error (dB) | max phase error (°) |",
            "|---|---|---|",
        ]
        for ch, v in bd["channels"].items():
            lines.append(f"| {ch} | {v['max_db']:.2f} | {v['max_deg']:.2f} |")
        lines += ["", f"![bode]({res['figures']['bode']})", ""]
    return "\n".join(lines) + "\n"


def run(out: Path, quick: bool = False) -> dict[str, Any]:
    """Run the benchmark; write ``out/controllers.md`` and ``out/controllers/*.png``.

    Returns a plain summary per joint (RMS errors in output rad, reductions in
    percent, load-step and point-to-point metrics, Bode errors).
    """
    t0 = time.time()
    out = Path(out)
    cfg = settings(quick)
    results: dict[str, Any] = {}
    for name in JOINTS:
        p = preset(name)
        res = {"cfg": cfg, "primary": PRIMARY[name],
               "tracking": {rev: tracking(p, cfg, rev, sweep_too=rev == PRIMARY[name])
                            for rev in SPEEDS},
               "load_step": load_step(p, cfg), "point_to_point": point_to_point(p, cfg),
               "bode": bode(p, cfg)}
        res["figures"] = _figures(name, res, out / "controllers")
        results[name] = res
    text = _markdown(results, quick, time.time() - t0)
    out.mkdir(parents=True, exist_ok=True)
    (out / "controllers.md").write_text(text)
    return summary(results)


def summary(results: dict[str, Any]) -> dict[str, Any]:
    """The numbers of a benchmark run without the time series."""
    out: dict[str, Any] = {}
    for name, res in results.items():
        ls, pp, bd = res["load_step"], res["point_to_point"], res["bode"]
        out[name] = {
            "tracking_rms": {rev: dict(t["rms"]) for rev, t in res["tracking"].items()},
            "tracking_reduction_pct": {rev: dict(t["reduction"])
                                       for rev, t in res["tracking"].items()},
            "primary_speed": res["primary"],
            "sweep_rms": dict(res["tracking"][res["primary"]]["sweep_rms"]),
            "load_step": {k: dict(v) for k, v in ls["metrics"].items()},
            "load_step_reduction_pct": ls["reduction"],
            "point_to_point": {k: dict(v) for k, v in pp["metrics"].items()},
            "bode": {k: {"max_db": v["max_db"], "max_deg": v["max_deg"]}
                     for k, v in bd["channels"].items()},
        }
    return out
