"""Hardware between a controller and the physics: action scaling and sensors.

The amplifier's current clip, back-EMF voltage limit and current loop act at
every physics substep, so they live in the compiled step
(:mod:`hdgym.physics.kernel`, effect ``amplifier_saturation``). This module
holds what happens once per control period:

* :func:`scale_actions`: normalized actions in [-1, 1] to current
  commands in A, for a batch (values outside saturate at the amplifier limit);
* :class:`SensorBank`: quantized input and output encoders, velocity
  estimated from counts, optional torque sensor, measurement noise and an
  optional one-sample delay, for a batch of joints.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from hdgym.physics import layout as L

#: names of the measured channels, in the order of :meth:`SensorBank.measure` rows
CHANNELS = (
    "motor_angle", "output_angle", "motor_velocity", "output_velocity", "output_torque",
    "motor_current",
)


@nb.njit(cache=True)
def _scale_actions(a: np.ndarray, limit: np.ndarray, clipped: np.ndarray,
                   current: np.ndarray) -> int:
    for i in range(a.shape[0]):
        v = float(a[i])
        if not math.isfinite(v):
            return i
        v = 1.0 if v > 1.0 else (-1.0 if v < -1.0 else v)
        clipped[i] = v
        current[i] = v * limit[i]
    return -1


def scale_actions(actions: np.ndarray, current_limit: np.ndarray, clipped: np.ndarray,
                  current: np.ndarray) -> None:
    """Map normalized actions to current commands, into preallocated arrays.

    ``action = 1`` asks for the amplifier's full current; larger values ask
    for more and are clipped by the amplifier exactly like an analog command
    beyond its range. ``clipped`` receives the actions clipped to [-1, 1],
    ``current`` the current commands (A) for per-env limits
    ``current_limit``. A NaN or infinite action raises ``ValueError`` naming
    the env.
    """
    bad = _scale_actions(actions, current_limit, clipped, current)
    if bad >= 0:
        raise ValueError(f"action must be finite, got {actions[bad]!r} for env {bad}")


def quantize(angle: np.ndarray, counts_per_rev: np.ndarray | float) -> np.ndarray:
    """Angle as an incremental encoder reports it (floor to whole counts), rad."""
    step = 2.0 * math.pi / np.asarray(counts_per_rev, dtype=float)
    return np.floor(np.asarray(angle) / step) * step


@nb.njit(cache=True)
def _read(xs: np.ndarray, steps: np.ndarray, prev: np.ndarray, dt: float, torque_sensor: bool,
          out: np.ndarray) -> None:
    """Noise-free reading of every env into ``out`` (rows in :data:`CHANNELS` order):
    encoders floored to whole counts (``steps`` rad per count, motor and output),
    velocities from the count difference to ``prev`` (updated), torque, current."""
    for i in range(xs.shape[0]):
        for k in range(2):
            a = math.floor(xs[i, L.TH_M if k == 0 else L.TH_O] / steps[k, i]) * steps[k, i]
            out[k, i] = a
            out[2 + k, i] = (a - prev[k, i]) / dt
            prev[k, i] = a
        out[4, i] = xs[i, L.TK] if torque_sensor else 0.0
        out[5, i] = xs[i, L.CUR]


class SensorBank:
    """Encoders, torque sensor and current measurement for ``n`` joints.

    Args:
        motor_counts, output_counts: counts per revolution (after decoding),
            scalars or per-env arrays.
        dt: sample period, s (velocity is the count difference over ``dt``).
        torque_sensor: if False the torque channel reads 0.
        torque_noise, current_noise: noise standard deviations, N m and A.
        delay: 0 or 1 samples of delay on every channel.
        rng: the seeded generator that draws the noise.
    """

    def __init__(self, n: int, motor_counts: np.ndarray | float, output_counts: np.ndarray | float,
                 dt: float, rng: np.random.Generator, torque_sensor: bool = True,
                 torque_noise: float = 0.0, current_noise: float = 0.0, delay: int = 0) -> None:
        if delay not in (0, 1):
            raise ValueError(f"sensors.delay must be 0 or 1 samples, got {delay!r}")
        if dt <= 0:
            raise ValueError(f"dt must be > 0 s, got {dt!r}")
        self.n = n
        self.motor_counts = np.broadcast_to(np.asarray(motor_counts, dtype=float), (n,))
        self.output_counts = np.broadcast_to(np.asarray(output_counts, dtype=float), (n,))
        self.dt = dt
        self.rng = rng
        self.torque_sensor = torque_sensor
        self.torque_noise = torque_noise
        self.current_noise = current_noise
        self.delay = delay
        # precomputed so a reading costs a handful of array operations, no allocation
        self._steps = 2.0 * math.pi / np.stack([self.motor_counts, self.output_counts])
        self._prev = np.zeros((2, n))
        self._held = np.zeros((len(CHANNELS), n))
        self._buf = np.zeros((len(CHANNELS), n))

    @classmethod
    def from_params(cls, n: int, sensors: object, dt: float, rng: np.random.Generator,
                    motor_counts: np.ndarray | None = None,
                    output_counts: np.ndarray | None = None) -> SensorBank:
        """Build from a :class:`hdgym.params.Sensors` (per-env counts may override)."""
        return cls(n, sensors.motor_counts if motor_counts is None else motor_counts,
                   sensors.output_counts if output_counts is None else output_counts, dt, rng,
                   sensors.torque_sensor, sensors.torque_noise, sensors.current_noise,
                   sensors.delay)

    def _raw(self, xs: np.ndarray, out: np.ndarray) -> np.ndarray:
        _read(xs, self._steps, self._prev, self.dt, self.torque_sensor, out)
        if self.torque_noise > 0 and self.torque_sensor:
            out[4] += self.rng.normal(0.0, self.torque_noise, self.n)
        if self.current_noise > 0:
            out[5] += self.rng.normal(0.0, self.current_noise, self.n)
        return out

    def reset(self, xs: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
        """Start counting from states ``xs`` for the envs in ``mask`` (all by default).

        Returns a reading ``(len(CHANNELS), n)`` with zero velocity estimates.
        """
        mask = np.ones(self.n, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        reading = np.zeros((len(CHANNELS), self.n))
        reading[:2] = np.floor(xs[:, [L.TH_M, L.TH_O]].T / self._steps) * self._steps
        reading[4] = xs[:, L.TK] if self.torque_sensor else 0.0
        reading[5] = xs[:, L.CUR]
        self._prev[:, mask] = reading[:2, mask]
        self._held[:, mask] = reading[:, mask]
        return reading

    def measure(self, xs: np.ndarray) -> np.ndarray:
        """Read all channels for states ``xs (n, N_STATE)``: array ``(len(CHANNELS), n)``.

        The returned array is a fresh copy the caller may keep.
        """
        if self.delay == 0:
            return self._raw(xs, self._buf).copy()
        out = self._held.copy()
        self._raw(xs, self._held)
        return out
