"""Small discrete filters for control loops, designed continuous and sampled with python-control."""

from __future__ import annotations

import math

import control
import numpy as np

from controllers.base import check_positive


class DiscreteFilter:
    """A SISO discrete filter stepped one sample at a time.

    Args:
        continuous: the continuous-time design (``control.tf`` or ``ss``).
        dt: sample period, s.
        method: discretization for :func:`control.sample_system`.
    """

    def __init__(self, continuous: control.LTI, dt: float, method: str = "tustin") -> None:
        self.dt = check_positive("dt", dt, "s")
        self.continuous = control.tf(continuous)
        self.discrete = control.sample_system(control.ss(continuous), self.dt, method=method)
        self._a = np.asarray(self.discrete.A, dtype=float)
        self._b = np.asarray(self.discrete.B, dtype=float)[:, 0]
        self._c = np.asarray(self.discrete.C, dtype=float)[0]
        self._d = float(np.asarray(self.discrete.D)[0, 0])
        self.reset()

    def reset(self, value: float = 0.0) -> None:
        """Start at the steady state for a constant input ``value``."""
        n = self._a.shape[0]
        self._x = np.linalg.solve(np.eye(n) - self._a, self._b * value) if n else np.zeros(0)

    def step(self, x: float) -> float:
        y = float(self._c @ self._x + self._d * x)
        self._x = self._a @ self._x + self._b * x
        return y


def notch(freq_hz: float, dt: float, *, width: float = 0.7, depth: float = 0.1
          ) -> control.TransferFunction:
    """Continuous notch ``(s^2 + 2 depth*width w s + w^2)/(s^2 + 2 width w s + w^2)``.

    Args:
        freq_hz: centre, Hz (> 0, below the Nyquist frequency ``0.5/dt``).
        dt: the sample period it will run at, s (for the Nyquist check).
        width: damping of the poles (> 0; larger is wider).
        depth: gain at the centre (0 < depth < 1).

    Raises:
        ValueError: naming the setting.
    """
    f = check_positive("freq_hz", freq_hz, "Hz")
    if f >= 0.5 / dt:
        raise ValueError(f"freq_hz must be below the Nyquist frequency {0.5 / dt:g} Hz, got "
                         f"{freq_hz!r}")
    zp = check_positive("width", width)
    if not 0 < depth < 1:
        raise ValueError(f"depth must be in (0, 1), got {depth!r}")
    w = 2 * math.pi * f
    return control.tf([1.0, 2 * depth * zp * w, w * w], [1.0, 2 * zp * w, w * w])
