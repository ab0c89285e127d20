"""Fourier-series repetitive control indexed by the WG angle.

The correction added to the output reference (output rad) is a Fourier
series of the WG angle ``theta`` (and optionally of the output angle)::

    c(theta) = c0 + sum_n a_n cos(n theta) + b_n sin(n theta)

Each sample the coefficients move along the output tracking error
``e = reference - output_angle`` (output encoder) projected on each basis
function, weighted by the WG angle travelled since the last sample::

    a_n += L/pi * e * cos(n theta + phi_n) * |d theta|      (b_n with sin)
    c0  += L/(2 pi) * e * |d theta|

so one WG revolution moves a coefficient by ``L`` times that revolution's
Fourier coefficient of the error: the classic per-period update of
repetitive control. Because learning and correction are indexed by angle,
not time, the memory stays valid while the speed changes, and nothing is
learnt at standstill.

Stability (per order n, WG speed w): let ``T(s)`` be the closed-loop
response from the reference seen by the wrapped controller to the output
angle (:func:`controllers.tuning.closed_loop`) and
``G_n = T(j n w) exp(j phi_n)``. One revolution maps the error coefficient
``E -> (1 - L G_n) E``, so learning converges iff, at every order and
every speed used,

    |1 - L G_n| < 1      (equivalently 0 < L < 2 Re(G_n) / |G_n|^2).

Below the loop bandwidth ``T ~ 1`` and the condition reads ``0 < L < 2``,
which the constructor enforces; :meth:`RepetitiveController.check_stability`
evaluates the full condition on a closed-loop model and raises if it fails.
(The per-sample update is the continuous-angle version of the per-period
map; for ``L`` well inside the bound the two agree.)
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from controllers.base import (
    Controller,
    Measurement,
    check_finite,
    check_nonneg,
    check_orders,
    check_positive,
)


class RepetitiveController:
    """Angle-indexed Fourier repetitive control around a position controller.

    Args:
        controller: the wrapped position controller (its reference is shifted).
        ratio: motor angle per output angle.
        orders: orders of the WG angle (cycles per WG revolution, > 0).
        gain: learning gain ``L`` per WG revolution, 0 < L < 2 (see module doc).
        output_orders: orders of the output angle (cycles per output revolution).
        output_gain: learning gain per output revolution for ``output_orders``.
        bias: also learn a constant term (mean wind-up), learnt per WG revolution.
        phase: phase lead phi_n per WG order, rad (default 0).
        limit: largest correction, output rad (> 0).
        start: seconds before learning starts (let transients settle), s.
        output_offset: added to the measured output angle before learning,
            output rad; incremental encoders floor to whole counts, so half
            a count (``pi / output_counts``) centres the reading.

    Raises:
        ValueError: naming the setting (non-positive orders, gain outside
            (0, 2), negative limit, ...).
    """

    def __init__(self, controller: Controller, ratio: float, orders: Sequence[float] = (1, 2, 4),
                 gain: float = 0.5, *, output_orders: Sequence[float] = (),
                 output_gain: float = 0.5, bias: bool = True,
                 phase: Mapping[float, float] | None = None, limit: float = 0.01,
                 start: float = 0.0, output_offset: float = 0.0) -> None:
        self.controller = controller
        self.ratio = check_positive("ratio", ratio)
        self.orders = check_orders("orders", orders)
        self.output_orders = check_orders("output_orders", output_orders) if len(
            output_orders) else ()
        self.gain = _check_gain("gain", gain)
        self.output_gain = _check_gain("output_gain", output_gain)
        self.bias = bool(bias)
        self.limit = check_positive("limit", limit, "output rad")
        self.start = check_nonneg("start", start, "s")
        self.output_offset = check_finite("output_offset", output_offset)
        phase = dict(phase or {})
        for k in phase:
            if float(k) not in self.orders:
                raise ValueError(f"phase: order {k!r} is not one of orders {self.orders}")
        self.phase = np.array([check_finite(f"phase[{n}]", phase.get(n, 0.0))
                               for n in self.orders])
        self._n = np.array(self.orders)
        self._no = np.array(self.output_orders)
        self.clear()
        self.reset_run()

    # ----------------------------------------------------------------- memory
    def clear(self) -> None:
        """Forget everything learnt."""
        self.a = np.zeros(len(self.orders))
        self.b = np.zeros(len(self.orders))
        self.ao = np.zeros(len(self.output_orders))
        self.bo = np.zeros(len(self.output_orders))
        self.c0 = 0.0

    def reset_run(self) -> None:
        self._prev_wg: float | None = None
        self._prev_out: float | None = None
        self.last_correction = 0.0

    def reset(self) -> None:
        """New run: reset the wrapped controller; keep the learnt series (see :meth:`clear`)."""
        self.controller.reset()
        self.reset_run()

    def coefficients(self) -> dict[str, Any]:
        """Learnt coefficients (output rad): orders, cos, sin, output terms, bias."""
        return {"orders": self.orders, "cos": self.a.copy(), "sin": self.b.copy(),
                "output_orders": self.output_orders, "output_cos": self.ao.copy(),
                "output_sin": self.bo.copy(), "bias": self.c0}

    # ----------------------------------------------------------------- law
    def correction(self, theta_wg: float, theta_out: float) -> float:
        """Correction at WG angle ``theta_wg`` and output angle ``theta_out``, output rad."""
        c = self.c0 + float(self.a @ np.cos(self._n * theta_wg) + self.b @ np.sin(
            self._n * theta_wg))
        if self._no.size:
            c += float(self.ao @ np.cos(self._no * theta_out)
                       + self.bo @ np.sin(self._no * theta_out))
        return min(max(c, -self.limit), self.limit)

    def learn(self, error: float, theta_wg: float, theta_out: float) -> None:
        """One learning step from the output error (output rad) at the measured angles."""
        if self._prev_wg is None:
            self._prev_wg, self._prev_out = theta_wg, theta_out
            return
        d = abs(theta_wg - self._prev_wg)
        do = abs(theta_out - self._prev_out)
        self._prev_wg, self._prev_out = theta_wg, theta_out
        if d > 0:
            arg = self._n * theta_wg + self.phase
            k = self.gain / math.pi * error * d
            self.a += k * np.cos(arg)
            self.b += k * np.sin(arg)
            if self.bias:
                self.c0 += 0.5 * k
        if do > 0 and self._no.size:
            k = self.output_gain / math.pi * error * do
            self.ao += k * np.cos(self._no * theta_out)
            self.bo += k * np.sin(self._no * theta_out)

    def __call__(self, t: float, measurement: Measurement) -> float:
        ref = measurement["reference"]
        if t >= self.start:
            y = measurement["output_angle"] + self.output_offset
            self.learn(ref - y, measurement["motor_angle"], y)
        self.last_correction = self.correction(self.ratio * ref, ref)
        m = dict(measurement)
        m["reference"] = ref + self.last_correction
        return self.controller(t, m)

    # ----------------------------------------------------------------- stability
    def contraction(self, closed_loop: Any, wg_speeds: Sequence[float]) -> np.ndarray:
        """``|1 - L G_n|`` for every WG order (rows) and WG speed (columns, rad/s).

        ``closed_loop`` is a SISO python-control system (continuous or
        discrete) from the shifted reference to the output angle, or any
        callable ``f(omega_rad_s) -> complex``.
        """
        speeds = np.abs(np.asarray(wg_speeds, dtype=float))
        if speeds.size == 0 or not np.all(speeds > 0):
            raise ValueError("wg_speeds must be positive speeds, rad/s")
        out = np.empty((len(self.orders), speeds.size))
        for i, n in enumerate(self.orders):
            g = _response(closed_loop, n * speeds) * np.exp(1j * self.phase[i])
            out[i] = np.abs(1.0 - self.gain * g)
        return out

    def check_stability(self, closed_loop: Any, wg_speeds: Sequence[float]) -> float:
        """Worst per-revolution contraction factor; raise ``ValueError`` if it is >= 1."""
        worst = float(self.contraction(closed_loop, wg_speeds).max())
        if not worst < 1.0:
            raise ValueError(f"gain: learning gain {self.gain} violates |1 - L G_n| < 1 "
                             f"(worst {worst:.3g}) at the given orders and speeds")
        return worst


def model_phase(closed_loop: Any, orders: Sequence[float], wg_speed: float) -> dict[float, float]:
    """Phase leads ``phi_n = -angle T(j n w)`` that make every ``G_n`` real at WG speed ``w``.

    With these, the condition becomes ``0 < L < 2/|T(j n w)|`` at that
    speed; check other speeds with :meth:`RepetitiveController.check_stability`.

    Args:
        closed_loop: the ``T(s)`` of the module doc (python-control system or callable).
        orders: WG orders.
        wg_speed: nominal WG speed, rad/s (> 0).
    """
    w = check_positive("wg_speed", abs(wg_speed), "rad/s")
    orders = check_orders("orders", orders)
    g = _response(closed_loop, np.array(orders) * w)
    return {n: float(-np.angle(v)) for n, v in zip(orders, g, strict=True)}


def _check_gain(name: str, gain: float) -> float:
    g = check_finite(name, gain)
    if not 0 < g < 2:
        raise ValueError(f"{name} must be in (0, 2) (learning converges only for 0 < L < 2 "
                         f"where the loop follows, T ~ 1), got {gain!r}")
    return g


def _response(sys: Any, omega: np.ndarray) -> np.ndarray:
    if callable(sys) and not hasattr(sys, "frequency_response"):
        return np.array([complex(sys(w)) for w in omega])
    resp = sys.frequency_response(omega)
    return np.asarray(resp.complex).reshape(-1)
