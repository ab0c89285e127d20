"""Identification of the torsion model from locked-output records.

The model is seed 002's: a two-segment spring (slope ``k1`` inside
``+-theta0``, ``k1 + k0`` outside) in parallel with ``n`` Maxwell-slip
elements (spring ``kappa_i`` in series with a slip block of strength
``W_i``)::

    T = k1 x + k0 (|x| - theta0)+ sgn(x) + sum_i kappa_i * stop(x, Delta_i)

where ``x`` is the torsion (output rad), ``Delta_i = W_i / kappa_i`` the slip
threshold of element ``i`` and ``stop`` the elastic-plastic (stop) operator
``s_k = clip(s_{k-1} + x_k - x_{k-1}, -Delta, Delta)`` started at zero
(relaxed elements, as the simulator starts). For fixed thresholds and knee
the torque is *linear* in ``(k1, k0, kappa_1..n)``, so :func:`fit_maxwell_slip`
uses variable projection: bounded nonlinear least squares
(:func:`scipy.optimize.least_squares`) over ``log Delta_i`` and ``theta0``,
with the non-negative linear parameters solved inside by
:func:`scipy.optimize.nnls`, started from the best of a small grid.

:func:`nmse` is seed 002's fit measure, ``NMSE% = 100/(n sigma^2) sum (y_hat - y)^2``
with ``sigma`` the standard deviation of the measured ``y``.

Identifiability (what a fit can and cannot tell from a record made by
another model): a Maxwell-slip model obeys Masing's rules, so all its loops
follow from one function, the *virgin curve* ``T_v(x) = spring(x) + sum_i
kappa_i clip(x, -Delta_i, Delta_i)`` (loading from the relaxed state). A
record determines ``T_v`` only over the torsion it excited, ``|x| <=
x_max``: elements with ``Delta_i > x_max`` never slip and are
indistinguishable from the spring, and many element sets give the same
``T_v`` there. :func:`virgin_curve_error` compares a fit's virgin curve with
a truth's inside and beyond the excited range, :func:`cycle_energy` the
energy a loop dissipates (for truths that are not Maxwell-slip, such as
Seyfferth's tanh element whose width grows with the cycle's peak load).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numba as nb
import numpy as np
from scipy.optimize import least_squares, nnls

from hdgym.params import JointParams


def nmse(y_hat: np.ndarray, y: np.ndarray) -> float:
    """Normalized mean squared error in percent (seed 002): ``100 mean((y_hat-y)^2) / var(y)``.

    Args:
        y_hat: model output.
        y: measured data (its variance normalizes the error).

    Raises:
        ValueError: if the shapes differ, ``y`` is constant or anything is not finite.
    """
    y_hat = np.asarray(y_hat, dtype=float)
    y = np.asarray(y, dtype=float)
    if y_hat.shape != y.shape:
        raise ValueError(f"nmse: shapes differ, {y_hat.shape} vs {y.shape}")
    if not (np.all(np.isfinite(y_hat)) and np.all(np.isfinite(y))):
        raise ValueError("nmse: inputs must be finite")
    var = float(np.var(y))
    if not var > 0:
        raise ValueError("nmse: the measured signal is constant (zero variance)")
    return 100.0 * float(np.mean((y_hat - y) ** 2)) / var


@nb.njit(cache=True)
def _stop(x: np.ndarray, delta: float) -> np.ndarray:
    out = np.empty_like(x)
    s = 0.0
    prev = x[0]
    for k in range(x.shape[0]):
        s += x[k] - prev
        prev = x[k]
        if s > delta:
            s = delta
        elif s < -delta:
            s = -delta
        out[k] = s
    return out


def stop_operator(x: np.ndarray, delta: float) -> np.ndarray:
    """Elastic-plastic (stop) operator with threshold ``delta``, starting relaxed at ``x[0]``.

    ``kappa * stop_operator(x, W / kappa)`` is the force of a Maxwell-slip
    element of stiffness ``kappa`` and slip strength ``W`` driven by ``x``.
    """
    if not delta >= 0:
        raise ValueError(f"stop_operator: delta must be >= 0, got {delta!r}")
    return _stop(np.ascontiguousarray(x, dtype=float), float(delta))


def play_operator(x: np.ndarray, delta: float) -> np.ndarray:
    """Backlash (play) operator: ``x - stop_operator(x, delta)`` (slip-block position)."""
    x = np.asarray(x, dtype=float)
    return x - stop_operator(x, delta)


def _knee_term(x: np.ndarray, theta0: float) -> np.ndarray:
    return np.maximum(np.abs(x) - theta0, 0.0) * np.sign(x)


@dataclass(frozen=True)
class MaxwellSlipFit:
    """A fitted two-segment spring + Maxwell-slip model (output-referred SI units).

    Attributes:
        k1: inner spring slope, N m/rad.
        k0: extra slope outside the knee, N m/rad.
        theta0: knee, rad.
        kappa: element stiffnesses, N m/rad.
        strength: element slip strengths W_i = kappa_i Delta_i, N m.
        nmse: training NMSE, percent.
    """

    k1: float
    k0: float
    theta0: float
    kappa: tuple[float, ...]
    strength: tuple[float, ...]
    nmse: float

    @property
    def thresholds(self) -> tuple[float, ...]:
        """Slip thresholds Delta_i = W_i / kappa_i, rad (inf for a zero element)."""
        return tuple(w / k if k > 0 else float("inf") for k, w in zip(self.kappa, self.strength,
                                                                      strict=True))

    def spring(self, x: np.ndarray) -> np.ndarray:
        """Torque of the two-segment spring alone, N m."""
        x = np.asarray(x, dtype=float)
        return self.k1 * x + self.k0 * _knee_term(x, self.theta0)

    def predict(self, torsion: np.ndarray) -> np.ndarray:
        """Torque for a torsion series (elements relaxed at its first sample), N m."""
        x = np.asarray(torsion, dtype=float)
        out = self.spring(x)
        for k, w in zip(self.kappa, self.strength, strict=True):
            if k > 0:
                out = out + k * stop_operator(x, w / k)
        return out

    def virgin_curve(self, x: np.ndarray) -> np.ndarray:
        """Torque when loading monotonically from the relaxed state to torsion ``x``, N m."""
        x = np.asarray(x, dtype=float)
        out = self.spring(x)
        for k, w in zip(self.kappa, self.strength, strict=True):
            if k > 0:
                out = out + k * np.clip(x, -w / k, w / k)
        return out

    def reversal_stiffness(self, resolution: float = 0.0) -> float:
        """Tangent stiffness just after a reversal, N m/rad: the spring's inner slope plus
        every element whose slip threshold exceeds ``resolution`` rad (elements that slip
        within one resolution step act as friction, not stiffness)."""
        return self.k1 + sum(k for k, d in zip(self.kappa, self.thresholds, strict=True)
                             if d > resolution)

    def saturated_strength(self, x_max: float) -> float:
        """Sum of the slip strengths of the elements that slip below torsion ``x_max``, N m
        (the half-height the hysteresis reaches in loops of amplitude ``x_max``)."""
        return sum(w for w, d in zip(self.strength, self.thresholds, strict=True) if d <= x_max)

    @classmethod
    def from_params(cls, p: JointParams) -> MaxwellSlipFit:
        """The torsion model of a preset with a linear or two-segment spring and Maxwell-slip
        hysteresis (a truth to compare fits with); ``nmse`` is NaN.

        Raises:
            ValueError: for another spring or hysteresis model.
        """
        c, h = p.compliance, p.hysteresis
        if c.model not in ("linear", "two_segment") or h.model != "maxwell":
            raise ValueError(f"from_params: {p.name} has a {c.model} spring and {h.model} "
                             "hysteresis; only linear/two_segment + maxwell map to this model")
        two = c.model == "two_segment"
        return cls(k1=c.stiffness, k0=c.extra_stiffness if two else 0.0,
                   theta0=c.knee if two else 0.0, kappa=tuple(h.element_stiffness),
                   strength=tuple(h.element_strength), nmse=math.nan)

    def as_params(self) -> dict[str, object]:
        """Keyword arguments for :class:`hdgym.params.Compliance` and ``Hysteresis``."""
        return {
            "compliance": {"model": "two_segment", "stiffness": self.k1,
                           "extra_stiffness": self.k0, "knee": self.theta0},
            "hysteresis": {"model": "maxwell", "element_stiffness": self.kappa,
                           "element_strength": self.strength},
        }


def _design(x: np.ndarray, deltas: np.ndarray, theta0: float) -> np.ndarray:
    cols = [x, _knee_term(x, theta0)] + [_stop(x, float(d)) for d in deltas]
    return np.column_stack(cols)


def _solve(x: np.ndarray, y: np.ndarray, z: np.ndarray, n: int, scale: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray]:
    deltas = np.exp(z[:n])
    theta0 = float(z[n])
    a = _design(x, deltas, theta0) * scale
    # NNLS on the small triangular factor: ||a c - y|| = ||r c - q'y|| + const
    q, r = np.linalg.qr(a)
    coef, _ = nnls(r, q.T @ y, maxiter=50 * a.shape[1])
    return coef * scale, a @ coef - y


def fit_maxwell_slip(torsion: np.ndarray, torque: np.ndarray, n_elements: int = 4,
                     max_nfev: int = 200) -> MaxwellSlipFit:
    """Fit a two-segment spring plus ``n_elements`` Maxwell-slip elements to a record.

    Args:
        torsion: flexspline torsion, output rad (locked output: ``motor_angle / ratio``).
        torque: measured flexspline torque, N m.
        n_elements: number of Maxwell-slip elements (>= 1).
        max_nfev: budget of the nonlinear search.

    Returns:
        The fit, with its training NMSE in percent.

    Raises:
        ValueError: on mismatched, non-finite or constant data.
    """
    x = np.ascontiguousarray(torsion, dtype=float)
    y = np.ascontiguousarray(torque, dtype=float)
    if x.shape != y.shape or x.ndim != 1 or x.size < 10:
        raise ValueError("fit_maxwell_slip: torsion and torque must be 1-D of equal length >= 10")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise ValueError("fit_maxwell_slip: data must be finite")
    if n_elements < 1:
        raise ValueError(f"fit_maxwell_slip: n_elements must be >= 1, got {n_elements}")
    span = float(np.max(x) - np.min(x))
    amp = float(np.max(np.abs(x)))
    if not span > 0:
        raise ValueError("fit_maxwell_slip: torsion is constant")
    # column scales so NNLS sees comparable columns
    n = n_elements
    lo_d, hi_d = span * 1e-4, span * 10.0
    scale = np.ones(n + 2)
    scale[0] = scale[1] = 1.0 / amp

    def resid(z: np.ndarray) -> np.ndarray:
        sc = scale.copy()
        sc[2:] = 1.0 / np.exp(z[:n])
        return _solve(x, y, z, n, sc)[1]

    # start: thresholds log-spaced, knee at a few quantiles of |x|
    best_z, best_cost = None, np.inf
    spreads = [np.geomspace(span * 1e-3, span * 0.3, n), np.geomspace(span * 1e-4, span * 0.05, n),
               np.geomspace(span * 1e-2, span * 1.0, n)]
    knees = np.quantile(np.abs(x), [0.0, 0.2, 0.5, 0.8])
    for d0, t0 in itertools.product(spreads, knees):
        z0 = np.concatenate([np.log(d0), [t0]])
        cost = float(np.sum(resid(z0) ** 2))
        if cost < best_cost:
            best_z, best_cost = z0, cost
    lower = np.concatenate([np.full(n, np.log(lo_d)), [0.0]])
    upper = np.concatenate([np.full(n, np.log(hi_d)), [amp]])
    z0 = np.clip(best_z, lower + 1e-12, upper - 1e-12)
    sol = least_squares(resid, z0, bounds=(lower, upper), x_scale=np.concatenate(
        [np.ones(n), [max(amp, 1e-12) * 0.1]]), max_nfev=max_nfev, diff_step=1e-4)
    sc = scale.copy()
    sc[2:] = 1.0 / np.exp(sol.x[:n])
    coef, r = _solve(x, y, sol.x, n, sc)
    deltas = np.exp(sol.x[:n])
    kappa = coef[2:]
    order = np.argsort(deltas)
    return MaxwellSlipFit(
        k1=float(coef[0]), k0=float(coef[1]), theta0=float(sol.x[n]),
        kappa=tuple(float(kappa[i]) for i in order),
        strength=tuple(float(kappa[i] * deltas[i]) for i in order),
        nmse=nmse(r + y, y),
    )


def virgin_curve_error(fit: MaxwellSlipFit, truth: MaxwellSlipFit, x_max: float,
                       n: int = 201) -> tuple[float, float]:
    """Largest virgin-curve difference inside and beyond the excited torsion range.

    Args:
        fit: the identified model.
        truth: the model that made the record.
        x_max: largest |torsion| of the training record, rad.
        n: grid points per range.

    Returns:
        ``(inside, beyond)``: max |T_fit - T_truth| over ``0 <= x <= x_max`` and over
        ``x_max <= x <= 2 x_max``, each in percent of the truth's torque at ``x_max``.
    """
    if not x_max > 0:
        raise ValueError(f"virgin_curve_error: x_max must be > 0 rad, got {x_max!r}")
    ref = abs(float(truth.virgin_curve(np.array([x_max]))[0]))
    if not ref > 0:
        raise ValueError("virgin_curve_error: the truth carries no torque at x_max")
    out = []
    for lo, hi in ((0.0, x_max), (x_max, 2.0 * x_max)):
        x = np.linspace(lo, hi, n)
        out.append(100.0 * float(np.max(np.abs(fit.virgin_curve(x) - truth.virgin_curve(x)))) / ref)
    return out[0], out[1]


def cycle_energy(torsion: np.ndarray, torque: np.ndarray) -> float:
    """Energy a closed torque/torsion loop dissipates, ``|closed integral of T dx|``, J.

    The samples should span whole cycles; the loop is closed from the last
    sample back to the first.
    """
    x = np.asarray(torsion, dtype=float)
    y = np.asarray(torque, dtype=float)
    if x.shape != y.shape or x.ndim != 1 or x.size < 3:
        raise ValueError("cycle_energy: torsion and torque must be 1-D of equal length >= 3")
    xc = np.append(x, x[0])
    yc = np.append(y, y[0])
    return float(abs(np.sum(0.5 * (yc[1:] + yc[:-1]) * np.diff(xc))))
