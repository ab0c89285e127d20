"""Simulator: run a joint on a command signal, open or closed loop, into a Record.

Rows follow the zero-order-hold convention of a data logger: row ``k`` holds
the state measured at ``time[k] = k * ctrl_dt`` and the command applied from
``time[k]`` to ``time[k+1]``. So re-simulating a record's command from its
first state reproduces it.
"""

from __future__ import annotations

import math
import numbers
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from hdgym.commands import command_signal
from hdgym.effects import flags_of
from hdgym.hardware import CHANNELS, SensorBank
from hdgym.params import JointParams
from hdgym.physics import kernel
from hdgym.physics import layout as L
from hdgym.record import Record

BYTES_PER_PERIOD = 8 * (2 * L.N_STATE + 2 * len(CHANNELS) + 8)
"""Memory a run takes per control period (states, measurements, record columns, copies)."""


def _memory_bytes() -> int:
    """Physical memory of this machine, bytes (a large number where unknown)."""
    try:
        return os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):  # pragma: no cover - not POSIX
        return 1 << 40


def _size(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if n < 1024 or unit == "PiB":
            return f"{n:.3g} {unit}"
        n /= 1024
    raise AssertionError  # pragma: no cover


class SimulationError(RuntimeError):
    """The integration diverged; the message says when and which state."""


class Controller(Protocol):
    """What the closed-loop runner drives: measurements in, current command (A) out."""

    def reset(self) -> None: ...

    def __call__(self, t: float, measurement: Mapping[str, float]) -> float: ...


def diverged_message(states: np.ndarray, k: int, dt: float) -> str:
    """Which state went bad at step ``k``."""
    row = states[k] if states.ndim == 2 else states
    for j, name in enumerate(L.STATE_NAMES):
        if not np.isfinite(row[j]):
            return f"simulation diverged at t = {k * dt:.6g} s: state {name} = {row[j]!r}"
    worst = int(np.argmax(np.abs(row[: L.HZ])))
    return (f"simulation diverged at t = {k * dt:.6g} s: state {L.STATE_NAMES[worst]} = "
            f"{row[worst]:.3g} (runaway; is the substep too large for this drive?)")


def _signal(value: float | np.ndarray | str | None, time: np.ndarray, what: str,
            rng: np.random.Generator) -> np.ndarray:
    if value is None:
        return np.zeros(time.shape)
    if np.isscalar(value) and not isinstance(value, str):
        value = np.full(time.shape, float(value))
    out = command_signal(value, time, rng)
    if not np.all(np.isfinite(out)):
        raise ValueError(f"{what}: not finite")
    return out


@dataclass
class Simulator:
    """A joint, ready to run.

    Args:
        params: the joint (effects switched in ``params.effects``).
        locked_output: clamp the output port (torsion experiments).
        sensors: record what the hardware measures (quantized encoders,
            velocity from counts, sensor noise); False records true states.
    """

    params: JointParams
    locked_output: bool = False
    sensors: bool = True
    row: np.ndarray = field(init=False, repr=False)
    flags: int = field(init=False)

    def __post_init__(self) -> None:
        self.row = L.pack(self.params)
        self.flags = flags_of(self.params.effects, self.locked_output)

    @property
    def ctrl_dt(self) -> float:
        return self.params.integration.ctrl_dt

    @property
    def n_substeps(self) -> int:
        return int(self.params.integration.n_substeps)

    def initial_state(self, motor_angle: float = 0.0) -> np.ndarray:
        """At rest, spring relaxed (output at zero if locked)."""
        out = 0.0 if self.locked_output else None
        return L.initial_state(self.row[None, :], self.flags, motor_angle, out)[0]

    def time(self, duration: float) -> np.ndarray:
        """Sample times of a run of ``duration`` s (one per control period).

        Raises:
            ValueError: naming ``duration`` if it is not a finite number of
                seconds, shorter than two control periods, or longer than this
                machine's memory can hold as a record (checked before allocating).
        """
        if isinstance(duration, bool) or not isinstance(duration, numbers.Real):
            raise ValueError(f"duration must be a number of seconds, got {duration!r} "
                             f"({type(duration).__name__})")
        if not math.isfinite(duration):
            raise ValueError(f"duration must be a finite number of seconds, got {duration!r}")
        n = round(duration / self.ctrl_dt)
        if not (duration > 0 and n >= 2):
            raise ValueError(f"duration must be at least two control periods "
                             f"({2 * self.ctrl_dt:g} s), got {duration!r} s")
        need, have = n * BYTES_PER_PERIOD, _memory_bytes()
        if need > have:
            raise ValueError(f"duration {duration:g} s is {n:,} control periods of "
                             f"{self.ctrl_dt:g} s, a record of about {_size(need)}, more than "
                             f"this machine's {_size(have)} of memory; run it in shorter pieces")
        return np.arange(n) * self.ctrl_dt

    def run(self, command: str | np.ndarray, duration: float | None = None, *, seed: int = 0,
            load_torque: float | np.ndarray | str | None = None,
            state: np.ndarray | None = None) -> Record:
        """Open-loop run of a current command.

        Args:
            command: a command spec (see :mod:`hdgym.commands`) or an array of
                currents, A, one per control period.
            duration: s (needed for a spec; an array sets its own length).
            seed: seeds the ``random`` command and the sensor noise.
            load_torque: external load torque, N m (scalar, array or spec).
            state: initial state (default: at rest, spring relaxed).
        """
        t, u, tl, states = self.trajectory(command, duration, seed=seed,
                                           load_torque=load_torque, state=state)
        return self._record(t, u, tl, states, np.random.default_rng([seed, 1]))

    def trajectory(self, command: str | np.ndarray, duration: float | None = None, *,
                   seed: int = 0, load_torque: float | np.ndarray | str | None = None,
                   state: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Like :meth:`run` but return the true states: ``(time, command, load, states)``.

        ``states`` has shape ``(n, N_STATE)`` (columns in
        :data:`hdgym.physics.layout.STATE_NAMES`).
        """
        if duration is None:
            if isinstance(command, str):
                raise ValueError("duration is needed for a command spec")
            duration = len(command) * self.ctrl_dt
        t = self.time(duration)
        rng = np.random.default_rng(seed)
        u = _signal(command, t, "command", rng)
        tl = _signal(load_torque, t, "load_torque", rng)
        x = self.initial_state() if state is None else state
        return t, u, tl, self.states(u, tl, x)

    def states(self, command: np.ndarray, load_torque: np.ndarray, state: np.ndarray
               ) -> np.ndarray:
        """The true states of a run from ``state`` (not changed), shape ``(n, N_STATE)``, the
        first row ``state``: :meth:`trajectory` without its checks, for callers that run many
        short pieces of arrays they have checked once (``command``, A, and ``load_torque``,
        N m: finite float arrays of equal length ``n``, one value per control period).

        Raises:
            SimulationError: the run diverged (naming the state and the time).
        """
        out = np.empty((command.size, L.N_STATE))
        x = np.array(state, dtype=float)
        out[0] = x
        bad = kernel.run_open_loop(x, self.row, command[:-1], load_torque[:-1],
                                   self.ctrl_dt / self.n_substeps, self.n_substeps, self.flags,
                                   out[1:])
        if bad >= 0:
            raise SimulationError(diverged_message(out[1:], bad, self.ctrl_dt))
        return out

    def run_closed_loop(self, controller: Controller | Callable[[float, Mapping[str, float]],
                                                                float],
                        duration: float, *, reference: Callable[[float], float] | None = None,
                        seed: int = 0, load_torque: float | np.ndarray | str | None = None,
                        state: np.ndarray | None = None) -> Record:
        """Closed-loop run: each period the controller sees the measurements and returns A.

        The measurement mapping has the channels of :data:`hdgym.hardware.CHANNELS`
        plus ``reference`` (output rad, when given) and ``time``.
        """
        t = self.time(duration)
        rng = np.random.default_rng(seed)
        tl = _signal(load_torque, t, "load_torque", rng)
        x = self.initial_state() if state is None else np.array(state, dtype=float)
        bank = self._bank(rng)
        xs = x[None, :]
        reading = bank.reset(xs)
        if hasattr(controller, "reset"):
            controller.reset()
        states = np.empty((t.size, L.N_STATE))
        meas = np.empty((t.size, len(CHANNELS)))
        u = np.zeros(t.size)
        ref = np.full(t.size, np.nan)
        dt = self.ctrl_dt / self.n_substeps
        trig = np.empty(kernel.SCRATCH)  # the kernel's per-env scratch, reused
        for k in range(t.size):
            states[k] = x
            meas[k] = reading[:, 0]
            m = {name: float(reading[j, 0]) for j, name in enumerate(CHANNELS)}
            m["time"] = float(t[k])
            if reference is not None:
                ref[k] = m["reference"] = float(reference(float(t[k])))
            cmd = float(controller(float(t[k]), m))
            if not np.isfinite(cmd):
                raise ValueError(f"controller returned {cmd!r} at t = {t[k]:.6g} s")
            u[k] = cmd
            if k + 1 < t.size:
                kernel.substeps(x, self.row, cmd, tl[k], dt, self.n_substeps, self.flags, trig)
                if kernel._bad(x):
                    raise SimulationError(diverged_message(x, k, self.ctrl_dt))
                reading = bank.measure(xs)
        extra = {"reference": ref} if reference is not None else {}
        return self._record(t, u, tl, states, rng, measured=meas if self.sensors else None,
                            extra=extra)

    def _bank(self, rng: np.random.Generator) -> SensorBank:
        return SensorBank.from_params(1, self.params.sensors, self.ctrl_dt, rng)

    def _record(self, t: np.ndarray, u: np.ndarray, tl: np.ndarray, states: np.ndarray,
                rng: np.random.Generator, measured: np.ndarray | None = None,
                extra: Mapping[str, np.ndarray] | None = None) -> Record:
        if self.sensors:
            if measured is None:
                bank = self._bank(rng)
                measured = np.empty((t.size, len(CHANNELS)))
                measured[0] = bank.reset(states[:1])[:, 0]
                for k in range(1, t.size):
                    measured[k] = bank.measure(states[k : k + 1])[:, 0]
            ch = {name: measured[:, j] for j, name in enumerate(CHANNELS)}
        else:
            ch = {
                "motor_angle": states[:, L.TH_M], "output_angle": states[:, L.TH_O],
                "motor_velocity": states[:, L.W_M], "output_velocity": states[:, L.W_O],
                "output_torque": states[:, L.TK], "motor_current": states[:, L.CUR],
            }
        cols = {"time": t, "current_command": u, "motor_current": ch["motor_current"],
                "motor_angle": ch["motor_angle"], "motor_velocity": ch["motor_velocity"]}
        if not self.locked_output:
            cols["output_angle"] = ch["output_angle"]
            cols["output_velocity"] = ch["output_velocity"]
        if self.params.sensors.torque_sensor or not self.sensors:
            cols["output_torque"] = ch["output_torque"]
        # the external load applied (the input a re-simulation needs); the model's own
        # constant load and gravity arm are parameters, not record columns
        cols["load_torque"] = tl
        cols.update(extra or {})
        meta = {
            "ratio": repr(self.params.ratio),
            "configuration": self.params.transmission.grounded,
            "locked_output": "true" if self.locked_output else "false",
            "preset": self.params.name,
            "source": "hdgym simulation" + ("" if self.sensors else " (true states)"),
        }
        return Record(columns={k: np.ascontiguousarray(v, dtype=float) for k, v in cols.items()},
                      meta=meta)
