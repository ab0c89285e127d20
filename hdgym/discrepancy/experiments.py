"""Identification protocols as current-command signals (docs/physics.md,
"Identification protocols").

``generate(name, params, duration=None, seed=0)`` returns a
:class:`~hdgym.record.Record` whose ``current_command`` (A) (and, for loaded
protocols, ``load_torque``, N m, the external load to apply) is the
protocol, scaled to the drive in ``params`` (amplifier limit, friction and
torque constant). The metadata names the protocol (``protocol``) and whether
the output must be locked (``locked_output``). Because a record always
carries the measured angles, the angle, speed, torque and current columns
hold the response the given ``params`` predict (``response: predicted``); a
rig uses only ``time``, ``current_command`` and ``load_torque``. A different
``seed`` gives a different realization of the same protocol (validation).

Protocols:

``locked_random``
    locked output, band-limited random current (RMS 30 % of the current
    limit, 5 Hz): torque-torsion loops, stiffness and hysteresis.
``slow_constant_speed``
    free output, a short breakaway kick then a constant current that holds
    the WG at a few revolutions per second: kinematic-error and
    position-dependent-friction order spectra.
``current_steps``
    free output, steps from the starting current up to the amplifier
    limit in both directions: friction against speed, Stribeck region,
    amplifier saturation.
``current_sine``
    free output, a slow sine of current (1 Hz, twice the starting current)
    so the speed rises and falls back through zero every half cycle: the
    Stribeck drop shows while decelerating, where stiction does not act.
``breakaway_ramps``
    free output, slow current ramps from rest to just past breakaway, a
    quick drop to zero and a pause in which the joint stops and sticks
    again, alternating directions: every ramp breaks away from rest, so
    the breakaway (static) friction shows against the running friction of
    the short run that follows.
``loaded_current_steps``
    free output, current steps while an external load torque steps too:
    load-dependent (tooth) friction.
"""

from __future__ import annotations

import math

import numpy as np

from hdgym.commands import command_signal
from hdgym.params import JointParams
from hdgym.record import Record
from hdgym.sim import Simulator

PROTOCOLS: dict[str, dict] = {
    "locked_random": {"locked": True, "duration": 4.0,
                      "use": "torque-torsion loops: stiffness, hysteresis"},
    "slow_constant_speed": {"locked": False, "duration": 4.0,
                            "use": "order spectra: kinematic error, position-dependent friction"},
    "current_steps": {"locked": False, "duration": 6.0,
                      "use": "friction against speed, Stribeck, amplifier saturation"},
    "current_sine": {"locked": False, "duration": 4.0,
                     "use": "speed through zero and back: Stribeck against stiction"},
    "breakaway_ramps": {"locked": False, "duration": 4.0,
                        "use": "breakaway against running friction (stiction)"},
    "loaded_current_steps": {"locked": False, "duration": 6.0,
                             "use": "friction against transmitted torque (tooth friction)"},
}

RAMP = (0.3, 0.02, 0.15)
"""Breakaway ramps: rise, drop and pause, s."""


def _running_current(p: JointParams, w_m: float) -> float:
    """Current that balances the friction of ``p`` at WG speed ``w_m`` (estimate, A)."""
    r = p.ratio
    fi, fo = p.friction.input, p.friction.output
    t_in = fi.coulomb + fi.viscous * w_m
    t_out = fo.coulomb + fo.viscous * w_m / r
    return (t_in + t_out / r) / p.motor.torque_constant


def _breakaway_current(p: JointParams) -> float:
    """Current that starts the joint from rest (static friction if the model has it), A."""
    fi, fo = p.friction.input, p.friction.output
    static = {"stiction", "stribeck_friction"} & set(p.effects)
    t_in = fi.breakaway if static else fi.coulomb
    t_out = fo.breakaway if static else fo.coulomb
    if "coulomb_friction" not in p.effects:
        t_in = t_out = 0.0
    return (t_in + t_out / p.ratio) / p.motor.torque_constant


def _imax(p: JointParams) -> float:
    return p.amplifier.current_limit


def _steps(levels: list[float], n: int) -> np.ndarray:
    per = max(n // len(levels), 1)
    u = np.repeat(np.asarray(levels, dtype=float), per)
    return np.pad(u, (0, max(n - u.size, 0)), mode="edge")[:n]


def command(name: str, p: JointParams, duration: float, seed: int = 0
            ) -> tuple[np.ndarray, np.ndarray | None]:
    """The protocol's current command (A) and external load (N m, or None) at ``ctrl_dt``."""
    if name not in PROTOCOLS:
        raise ValueError(f"experiment: unknown protocol {name!r}; known protocols are "
                         f"{', '.join(PROTOCOLS)}")
    if not duration > 0:
        raise ValueError(f"experiment: duration must be > 0 s, got {duration!r}")
    dt = p.integration.ctrl_dt
    n = max(int(round(duration / dt)), 2)
    t = np.arange(n) * dt
    rng = np.random.default_rng(seed)
    imax = _imax(p)
    ib = max(_breakaway_current(p), 0.02 * imax)
    if name == "locked_random":
        u = command_signal(f"random:{0.3 * imax}:5", t, rng)
        return np.clip(u, -0.9 * imax, 0.9 * imax), None
    if name == "slow_constant_speed":
        w_m = 2 * math.pi * 5.0 * (1 + 0.15 * rng.uniform(-1, 1))
        i_run = _running_current(p, w_m)
        sign = 1.0 if rng.uniform() < 0.5 else -1.0
        u = np.full(n, i_run)
        u[: int(0.05 / dt)] = max(1.3 * ib, 1.3 * i_run)
        return sign * np.minimum(u, 0.9 * imax), None
    if name == "current_steps":
        lv = np.geomspace(1.2 * ib, 0.95 * imax, 5) * (1 + 0.05 * rng.uniform(-1, 1, 5))
        levels = [v for v in lv] + [-v for v in lv]
        if rng.uniform() < 0.5:
            levels = [-v for v in levels]
        return _steps(levels, n), None
    if name == "current_sine":
        amp = min(2.0 * ib, 0.9 * imax) * (1 + 0.1 * rng.uniform(-1, 1))
        return amp * np.sin(2 * np.pi * 1.0 * t + rng.uniform(0, 2 * np.pi)), None
    if name == "breakaway_ramps":
        # per ramp: a slow rise from rest to just past breakaway, a quick drop to zero (a rig
        # stops the ramp once the joint moves) and a pause long enough for the joint to stop
        # and stick again; alternating directions, so every ramp breaks away from rest
        n_up, n_down, n_rest = int(RAMP[0] / dt), int(RAMP[1] / dt), int(RAMP[2] / dt)
        shape = np.concatenate([np.linspace(0.0, 1.0, n_up), np.linspace(1.0, 0.0, n_down),
                                np.zeros(n_rest)])
        static = {"stiction", "stribeck_friction"} & set(p.effects)
        # just past breakaway; without a static friction in the model, assume breakaway up
        # to twice the running friction
        peak = (1.2 if static else 2.4) * ib
        sign = 1.0 if rng.uniform() < 0.5 else -1.0
        parts = []
        k = 0
        while sum(x.size for x in parts) < n:
            parts.append(shape * peak * (1 + 0.05 * rng.uniform(-1, 1)) * sign * (-1) ** k)
            k += 1
        u = np.concatenate(parts)[:n]
        return np.clip(u, -0.9 * imax, 0.9 * imax), None
    # loaded_current_steps
    kt_out = p.motor.torque_constant * p.ratio
    lv = np.linspace(2.0 * ib, 0.6 * imax, 3)
    levels, loads = [], []
    for k, v in enumerate(lv):
        for s in (1, -1):
            levels.append(s * v * (1 + 0.05 * rng.uniform(-1, 1)))
            loads.append(s * (0.3 + 0.3 * k) * v * kt_out * 0.5)
    return _steps(levels, n), _steps(loads, n)


def generate(name: str, params: JointParams, duration: float | None = None,
             seed: int = 0) -> Record:
    """The protocol ``name`` for the drive ``params`` as a record (see the module docstring).

    Raises:
        ValueError: unknown protocol or bad duration (message names them).
    """
    if name not in PROTOCOLS:
        raise ValueError(f"experiment: unknown protocol {name!r}; known protocols are "
                         f"{', '.join(PROTOCOLS)}")
    spec = PROTOCOLS[name]
    duration = spec["duration"] if duration is None else float(duration)
    u, tl = command(name, params, duration, seed)
    sim = Simulator(params, locked_output=spec["locked"])
    rec = sim.run(u, seed=seed, load_torque=tl)
    meta = dict(rec.meta)
    meta.update({"protocol": name, "locked_output": "true" if spec["locked"] else "false",
                 "response": "predicted", "source": f"hdgym experiment {name} (seed {seed}); "
                 f"columns other than current_command and load_torque are the response "
                 f"predicted by {params.name}"})
    cols = dict(rec.columns)
    if tl is None:
        cols.pop("load_torque", None)
    return Record(cols, meta)
