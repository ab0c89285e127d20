"""Classical controller families for the resonance task, with per-env parameters.

Every family is one batched controller whose parameters are arrays with one
entry per env, so a whole tuning grid runs as one batch of the native vector
env (grid point ``j``, episode ``k`` in env ``j * n_episodes + k``). Each
controller sees the measured observation of ``HarmonicDriveResonance-v0``
only (:data:`agents.baselines` channel constants) and is called every
control period (``dt`` = the env's ``ctrl_dt``), like an SB3 policy through
``predict``.

Families (currents in A, speeds in rad/s of the motor):

* ``const``: constant current ``level``.
* ``pi``: the PI speed loop of :mod:`agents.baselines` (5 Hz, 60 deg), its
  output limited to ``limit``.
* ``pi_ramp``: the same PI on a ramp-limited reference
  ``min(target, rate * t)``, output limited to ``limit``.
* ``damp``: active damping of the torsion around a constant level,
  ``level - a + a tanh(gain * (cos(phi) x + sin(phi) dx / (w_n dt)))`` with
  ``x`` the torsion signal (torque sensor minus its running mean; with
  ``source = "encoders"`` the twist integrated from the encoder velocities,
  high-passed); ``level`` = the amplifier's full current is damping after
  (on top of) full current.
* ``two_phase``: run up at ``run`` A until the measured speed passes
  ``switch`` (rad/s), then the PI with output limit ``hold`` A: the
  bistable trap holds a joint above it with less current than it takes to
  break out.
* any family ``+ ke``: a feedforward ripple ``ke_amp cos(2 theta_wg + ke_phase)``
  (A) added to its command, against the 2x-order kinematic-error forcing.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from agents.baselines import OBS_COS, OBS_OSC, OBS_SIN, OBS_SPEED, OBS_TARGET, design_pi
from hdgym.params import JointParams

OBS_OUT_SPEED = 1  # measured output speed x ratio / target speed

FAMILIES = ("const", "pi", "pi_ramp", "damp", "two_phase")
#: names of the families in reports
FAMILY_LABELS = {
    "const": "constant current",
    "pi": "PI speed loop over current limits",
    "pi_ramp": "PI with ramp-limited reference",
    "damp": "torque-sensor damping",
    "damp_full": "torque-sensor damping on full current",
    "damp_enc": "encoder-torsion damping",
    "two_phase": "run up, then hold",
}


class FamilyController:
    """One batched controller of a family; ``params`` maps names to per-env arrays.

    Args:
        family: one of :data:`FAMILIES`.
        params: per-env arrays (or scalars) of the family's parameters, plus
            optional ``ke_amp`` (A) and ``ke_phase`` (rad).
        joint: the nominal joint (PI design, amplifier limits).
        speed_scale: the env's speed scale (normalizes the target observation), rad/s.
        dt: the call period, s. The controller keeps its own clock (``dt`` per call
            since :meth:`reset`): the time observation saturates at the env's
            horizon (3 s) while the long variant's episodes run on to 6 s, and
            ``pi_ramp`` needs the time all along.
        source: torsion signal of ``damp``: ``"torque"`` (torque sensor) or
            ``"encoders"`` (integrated encoder twist).
        f_n: Hz, the torsional frequency that scales the damping's rate term.
    """

    def __init__(self, family: str, params: Mapping[str, Any], joint: JointParams,
                 speed_scale: float, dt: float, source: str = "torque",
                 f_n: float = 44.0) -> None:
        if family not in FAMILIES:
            raise ValueError(f"family must be one of {FAMILIES}, got {family!r}")
        if source not in ("torque", "encoders"):
            raise ValueError(f"source must be 'torque' or 'encoders', got {source!r}")
        self.family = family
        self.p = {k: np.asarray(v, dtype=float) for k, v in params.items()}
        self.i_amp = joint.amplifier.current_limit
        self.v_max = joint.amplifier.voltage_limit
        self.kb = joint.motor.back_emf_constant
        self.res = joint.motor.resistance
        d = design_pi(joint)
        self.kp, self.ki = d.kp, d.ki
        self.tt = 0.5 * d.kp / d.ki
        self.speed_scale = speed_scale
        self.dt = dt
        self.source = source
        self.rate_scale = 1.0 / (2.0 * math.pi * f_n * dt)
        self.w_n = 2.0 * math.pi * f_n
        self.n = 0

    def reset(self, n: int) -> None:
        self.n = n
        self.integral = np.zeros(n)
        self.prev = np.full(n, np.nan)
        self.twist = np.zeros(n)
        self.switched = np.zeros(n, dtype=bool)
        self.t = np.zeros(n)  # s, since reset

    def _arr(self, name: str, default: float | None = None) -> np.ndarray:
        if name not in self.p:
            if default is None:
                raise ValueError(f"family {self.family!r} needs parameter {name!r}")
            return np.full(self.n, default)
        return np.broadcast_to(self.p[name], (self.n,))

    def _pi(self, target: np.ndarray, ref: np.ndarray, speed: np.ndarray,
            limit: np.ndarray) -> np.ndarray:
        """PI on ``ref``, output within ``limit`` and the back-EMF limit (A)."""
        e = ref - speed
        u = self.kp * e + self.integral
        hi = np.minimum(limit, (self.v_max - self.kb * speed) / self.res)
        lo = np.maximum(-limit, (-self.v_max - self.kb * speed) / self.res)
        u_sat = np.clip(u, np.minimum(lo, hi), hi)
        self.integral += self.dt * (self.ki * e + (u_sat - u) / self.tt)
        return u_sat

    def _torsion(self, obs: np.ndarray, target: np.ndarray) -> np.ndarray:
        """The torsion signal (normalized): torque oscillation or encoder twist."""
        if self.source == "torque":
            return obs[:, OBS_OSC]
        # twist rate, motor-referred rad/s, from the two encoder velocities;
        # integrated with a leak (time constant 5 / w_n) against drift and slow KE
        rate = (obs[:, OBS_SPEED] - obs[:, OBS_OUT_SPEED]) * target
        self.twist += self.dt * (rate - self.twist * self.w_n / 5.0)
        return self.twist * self.w_n / self.speed_scale * 20.0

    def command(self, obs: np.ndarray) -> np.ndarray:
        """Current command, A, of every env."""
        target = obs[:, OBS_TARGET] * self.speed_scale
        speed = obs[:, OBS_SPEED] * target
        t = self.t.copy()
        self.t += self.dt
        f = self.family
        if f == "const":
            u = self._arr("level").copy()
        elif f == "pi":
            u = self._pi(target, target, speed, self._arr("limit"))
        elif f == "pi_ramp":
            ref = np.minimum(target, self._arr("rate") * t)
            u = self._pi(target, ref, speed, self._arr("limit"))
        elif f == "damp":
            x = self._torsion(obs, target)
            first = np.isnan(self.prev)
            self.prev[first] = x[first]
            dx = (x - self.prev) * self.rate_scale
            self.prev = x.copy()
            phi = self._arr("phase")
            fb = np.cos(phi) * x + np.sin(phi) * dx
            a = self._arr("amp")
            u = self._arr("level") - a + a * np.tanh(self._arr("gain", 3.0) * fb)
        else:  # two_phase
            self.switched |= speed >= self._arr("switch")
            hold = self._pi(target, target, speed, self._arr("hold"))
            u = np.where(self.switched, hold, self._arr("run"))
            # the PI starts from the run-up current when it takes over
            self.integral = np.where(self.switched, self.integral, self._arr("hold"))
        if "ke_amp" in self.p:
            c, s = obs[:, OBS_COS], obs[:, OBS_SIN]
            c2, s2 = c * c - s * s, 2.0 * c * s
            ph = self._arr("ke_phase", 0.0)
            u = u + self._arr("ke_amp") * (c2 * np.cos(ph) - s2 * np.sin(ph))
        return u

    def predict(self, obs: np.ndarray, state: object = None,
                episode_start: np.ndarray | None = None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:
        obs = np.atleast_2d(np.asarray(obs, dtype=float))
        if obs.shape[0] != self.n:
            self.reset(obs.shape[0])
        u = np.clip(self.command(obs) / self.i_amp, -1.0, 1.0)
        return u[:, None].astype(np.float32), None


def grid(spec: Mapping[str, Sequence[float]]) -> list[dict[str, float]]:
    """Every combination of the values in ``spec`` (a product grid), as dicts."""
    keys = list(spec)
    return [dict(zip(keys, vals, strict=True)) for vals in itertools.product(*spec.values())]


def default_grids(i_max: float, quick: bool = False) -> dict[str, list[dict[str, float]]]:
    """The tuning grid of each family for an amplifier of ``i_max`` A.

    Keys: :data:`FAMILY_LABELS` names. Currents span the trap's plateau
    (Tuttle: 2.8-4.0 A settle in it on joint 1) up to full current; ramp
    rates span run-ups of about 0.8-5.5 s to the target (the slowest ones matter on the
    long variant's 6 s episodes only).
    """
    deg = math.radians
    levels = np.round(np.linspace(0.6, 1.0, 3 if quick else 9) * i_max, 3).tolist()
    rates = [deg(r) for r in ((4000, 8000) if quick else
                              (2000, 2500, 3000, 3500, 4500, 5500, 7000, 9000, 12000))]
    phases = [deg(p) for p in ((0, 90) if quick else (0, 90, 180, 270))]
    amps = [0.1 * i_max, 0.25 * i_max] if quick else [0.05 * i_max, 0.1 * i_max, 0.2 * i_max,
                                                       0.35 * i_max]
    g = {
        "const": grid({"level": levels}),
        "pi": grid({"limit": levels}),
        "pi_ramp": grid({"rate": rates, "limit": levels[-3:] if quick else levels[2:]}),
        "damp": grid({"level": levels[:-1], "amp": amps, "phase": phases}),
        "damp_full": grid({"level": [i_max], "amp": amps, "phase": phases}),
        "two_phase": grid({"run": levels[-2:] if quick else levels[3:],
                           "switch": [deg(s) for s in ((9000,) if quick else
                                                       (8500, 9000, 9500, 10000))],
                           "hold": [0.65 * i_max] if quick else [0.6 * i_max, 0.7 * i_max,
                                                                 0.85 * i_max]}),
    }
    return g


def ke_grid(base: Mapping[str, float], i_max: float,
            quick: bool = False) -> list[dict[str, float]]:
    """KE feedforward on top of one tuned point: ``base`` plus a 2x-order current ripple
    of each amplitude (A) and phase in the grid (and amplitude 0, the base alone)."""
    amps = (0.05 * i_max,) if quick else (0.025 * i_max, 0.05 * i_max, 0.1 * i_max)
    phases = (0.0, math.pi) if quick else tuple(math.radians(p) for p in range(0, 360, 45))
    pts = [{**base, "ke_amp": 0.0, "ke_phase": 0.0}]
    pts += [{**base, "ke_amp": a, "ke_phase": p} for a in amps for p in phases]
    return pts


def label(name: str) -> str:
    """Report name of a grid (``<grid>+ke``: that grid's pick with KE feedforward)."""
    base, plus, _ = name.partition("+")
    return FAMILY_LABELS.get(base, base) + (" + KE feedforward" if plus else "")


def family_of(name: str) -> tuple[str, str]:
    """(controller family, torsion source) of a grid name (``damp_full`` is ``damp``,
    ``<grid>+ke`` is the grid's family)."""
    name = name.partition("+")[0]
    if name in ("damp_full",):
        return "damp", "torque"
    if name == "damp_enc":
        return "damp", "encoders"
    return name, "torque"
