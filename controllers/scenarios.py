"""Closed-loop experiments shared by the benchmark and the tests.

Each function runs one scenario on :class:`hdgym.sim.Simulator` with the
hardware on (amplifier limits, quantized encoders) and returns the measured
:class:`hdgym.record.Record` together with the *true* states, recovered as a
second record by re-simulating the recorded current command from the same
initial state without sensors (the simulator is deterministic; see
:mod:`hdgym.sim`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from controllers.base import Controller
from controllers.pid import PositionPID
from controllers.tuning import design_pid, linearize, output
from hdgym.params import JointParams
from hdgym.sim import Simulator


@dataclass
class Run:
    """One closed-loop run: the measured record and the true states (a record of them)."""

    record: Any
    truth: Any
    reference: np.ndarray

    @property
    def time(self) -> np.ndarray:
        return np.asarray(self.record.time)

    @property
    def output_angle(self) -> np.ndarray:
        """True output angle, rad."""
        return np.asarray(self.truth.columns["output_angle"])

    @property
    def error(self) -> np.ndarray:
        """True output tracking error ``reference - output_angle``, output rad."""
        return self.reference - self.output_angle

    @property
    def measured_error(self) -> np.ndarray:
        """Output error as the output encoder sees it, output rad."""
        return self.reference - np.asarray(self.record.output_angle)


def closed_loop(p: JointParams, controller: Controller, duration: float,
                reference: Callable[[float], float], *, load_torque: Any = None,
                seed: int = 0) -> Run:
    """Run ``controller`` on ``p`` with sensors on; return measured and true data."""
    sim = Simulator(p, sensors=True)
    x0 = sim.initial_state()
    rec = sim.run_closed_loop(controller, duration, reference=reference, seed=seed,
                              load_torque=load_torque, state=x0)
    u = np.asarray(rec.columns["current_command"])
    tl = None if load_torque is None else _load_array(sim, load_torque, rec)
    truth = Simulator(p, sensors=False).run(u, state=x0, load_torque=tl, seed=seed)
    ref = np.asarray(rec.columns["reference"])
    return Run(record=rec, truth=truth, reference=ref)


def _load_array(sim: Simulator, load_torque: Any, rec: Any) -> np.ndarray:
    t = np.asarray(rec.time)
    if np.isscalar(load_torque):
        return np.full(t.shape, float(load_torque))
    return np.asarray(load_torque, dtype=float)


def ramp(speed: float, start: float = 0.0, ramp_time: float = 0.5) -> Callable[[float], float]:
    """Output reference rising at ``speed`` (output rad/s) after a smooth start, rad."""

    def ref(t: float) -> float:
        s = t - start
        if s <= 0:
            return 0.0
        if s < ramp_time:  # constant acceleration up to speed
            return 0.5 * speed / ramp_time * s * s
        return speed * (s - 0.5 * ramp_time)

    return ref


def min_jerk(distance: float, start: float, move_time: float) -> Callable[[float], float]:
    """Point-to-point minimum-jerk output reference of ``distance`` rad, rad."""

    def ref(t: float) -> float:
        s = (t - start) / move_time
        if s <= 0:
            return 0.0
        if s >= 1:
            return distance
        return distance * s ** 3 * (10 - 15 * s + 6 * s * s)

    return ref


def motor_pid(p: JointParams, crossover_hz: float | None = None,
              phase_margin_deg: float = 45.0, notch_filter: bool | None = None
              ) -> tuple[PositionPID, Any]:
    """Motor-angle PID designed with python-control on the linearized joint.

    ``notch_filter=None`` designs with and without the notch and keeps the
    one with the higher crossover. With ``notch_filter`` a notch
    (:func:`controllers.filters.notch`, width 0.35, depth 0.1) sits at the
    linear torsional resonance and is part of the design. The crossover
    starts at a quarter of the resonance and is lowered until
    :func:`controllers.tuning.loop_margins` reports the wanted phase margin
    (within 1 deg) and at least 6 dB gain margin on the whole loop, the
    resonance included; the sample-and-hold plus computation delay is
    modelled as one period. Inertia feedforward uses the nominal rigid-body
    inertia.
    """
    from controllers.filters import DiscreteFilter, notch
    from controllers.tuning import resonance_hz

    if notch_filter is None:
        a = motor_pid(p, crossover_hz, phase_margin_deg, False)
        b = motor_pid(p, crossover_hz, phase_margin_deg, True)
        return b if b[1].crossover_hz > a[1].crossover_hz else a

    dt = p.integration.ctrl_dt
    plant = output(linearize(p), "motor_angle")
    fres = resonance_hz(p)
    filt = notch(fres, dt, width=0.35) if notch_filter else None
    fc = fres / 4.0 if crossover_hz is None else crossover_hz
    design = None
    for _ in range(40):
        try:
            design = design_pid(plant, fc, phase_margin_deg, delay=dt, ti_over_td=2.0,
                                loop_filter=filt)
        except ValueError:
            if crossover_hz is not None:
                raise
            fc *= 0.9
            continue
        if (design.phase_margin_deg >= phase_margin_deg - 1.0
                and design.gain_margin_db >= 6.0) or crossover_hz is not None:
            break
        fc *= 0.9
    if design is None:
        raise ValueError(f"phase_margin_deg: no crossover below {fres / 4:.3g} Hz reaches "
                         f"{phase_margin_deg} deg")
    pid = design.pid(dt, p.amplifier.current_limit, derivative_on="error")
    j = p.motor.inertia + p.load.inertia / p.ratio ** 2
    ctrl = PositionPID(pid, p.ratio, feedback="motor",
                       inertia_feedforward=j / p.motor.torque_constant,
                       loop_filter=None if filt is None else DiscreteFilter(filt, dt))
    return ctrl, design


def rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def half_count(counts: int) -> float:
    """Half an encoder count, rad (incremental encoders floor to whole counts)."""
    return math.pi / counts


def speed_sweep(v0: float, v1: float, start: float, sweep_time: float,
                offset: float = 0.0) -> Callable[[float], float]:
    """Reference whose speed goes linearly from ``v0`` to ``v1`` (output rad/s), rad.

    Constant speed ``v0`` before ``start``; the angle continues from ``offset``.
    """

    def ref(t: float) -> float:
        if t <= start:
            return offset + v0 * t
        s = min(t - start, sweep_time)
        a = (v1 - v0) / sweep_time
        angle = offset + v0 * t + 0.5 * a * s * s
        if t - start > sweep_time:
            angle += (v1 - v0) * (t - start - sweep_time)
        return angle

    return ref


def ke_orders(ratio: float, grounded: str, base: tuple[float, ...] = (1.0, 2.0, 4.0)
              ) -> tuple[float, ...]:
    """WG orders to fit: ``base`` plus the split lines of the non-grounded spline.

    The non-grounded port's tooth errors appear at ``n (1 -+ 1/ratio)`` of the
    grounded-frame WG angle (docs/physics.md eq. (1)); the even base orders get one.
    """
    factor = 1.0 - 1.0 / ratio if grounded == "flexspline" else 1.0 + 1.0 / ratio
    extra = tuple(n * factor for n in base if n % 2 == 0)
    return tuple(sorted(base + extra))


def deviation_metrics(t: np.ndarray, dev: np.ndarray, t_step: float, band: float
                      ) -> dict[str, float]:
    """Peak |deviation| after ``t_step`` and the time until it stays within ``band``."""
    k = t >= t_step
    d = np.abs(dev[k])
    outside = np.nonzero(d > band)[0]
    recovery = float(t[k][outside[-1]] - t_step + (t[1] - t[0])) if outside.size else 0.0
    if outside.size and outside[-1] == d.size - 1:
        recovery = math.inf
    return {"peak": float(d.max()), "recovery": recovery}


def step_metrics(t: np.ndarray, y: np.ndarray, target: float, t_start: float,
                 band: float) -> dict[str, float]:
    """Overshoot (% of the move), settling time to ``band`` (s from ``t_start``)."""
    k = t >= t_start
    over = max(0.0, float(np.max(np.sign(target) * (y[k] - target)))) / abs(target) * 100
    outside = np.nonzero(np.abs(y[k] - target) > band)[0]
    settle = float(t[k][outside[-1]] - t_start + (t[1] - t[0])) if outside.size else 0.0
    if outside.size and outside[-1] == int(k.sum()) - 1:
        settle = math.inf
    return {"overshoot_pct": over, "settling_time": settle}
