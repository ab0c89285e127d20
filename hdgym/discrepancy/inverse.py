"""The inverse (equation-error) comparison: predicted current from the measured motion."""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from hdgym.effects import flags_of
from hdgym.params import JointParams
from hdgym.physics import kernel
from hdgym.physics import layout as L

from . import residuals as R


@nb.njit(cache=False)  # it inlines kernel code: a per-file cache would go stale with it
def inverse_friction(p, flags, w_m, th_m, th_o, w_o, t_k, mu, out_in, out_out):  # pragma: no cover
    for k in range(w_m.shape[0]):
        lvl = kernel._friction_level(p, L.FIN, w_m[k], th_m[k], th_o[k], 0.0, flags)
        vis = kernel._viscous_coeff(p, L.FIN, w_m[k], flags)
        out_in[k] = lvl * math.copysign(1.0, w_m[k]) + vis * w_m[k]
        lvl = kernel._friction_level(p, L.FOUT, w_o[k], th_m[k], th_o[k], mu * abs(t_k[k]), flags)
        vis = kernel._viscous_coeff(p, L.FOUT, w_o[k], flags)
        out_out[k] = lvl * math.copysign(1.0, w_o[k]) + vis * w_o[k]


class InverseComparison:
    """The inverse-dynamics part of :class:`.problem.Problem` (uses its record arrays)."""

    raw: R.Raw
    dt: float
    cutoff: float
    ratio: float
    t_ext: np.ndarray
    mask: np.ndarray | None

    def _prepare_inverse(self) -> None:
        th_o = lowpass_ = R.lowpass(self.raw.output_angle, self.dt, self.cutoff)
        self.th_o = lowpass_
        self.w_o = np.gradient(th_o, self.dt)
        self.a_o = np.gradient(self.w_o, self.dt)
        self.th_m = R.lowpass(self.raw.motor_angle, self.dt, self.cutoff)
        self.w_m = np.gradient(self.th_m, self.dt)
        vmax = float(np.quantile(np.abs(self.w_o), 0.95))
        self.mask = np.abs(self.w_o) > 0.2 * vmax
    def _inverse(self, p: JointParams) -> np.ndarray:
        """Predicted current from the measured motion (rigid joint, no measured torque used)."""
        row = L.pack(p)
        flags = flags_of(p.effects)
        r = self.ratio
        n = self.w_o.size
        f_in, f_out = np.empty(n), np.empty(n)
        kt = p.motor.torque_constant
        load = p.load
        t_load = load.torque + load.gravity * np.sin(self.th_o) + self.t_ext
        mu = row[L.MU_LOAD] if "load_dependent_friction" in p.effects else 0.0
        # transmitted torque T_k = J_o a + T_load + F_out(T_k): two fixed-point passes
        t_k = load.inertia * self.a_o + t_load
        for _ in range(2 if mu > 0 else 1):
            inverse_friction(row, flags, self.w_m, self.th_m, self.th_o, self.w_o, t_k, mu,
                              f_in, f_out)
            t_k = load.inertia * self.a_o + t_load + f_out
        t_m = p.motor.inertia * r * self.a_o + t_k / r + f_in
        return R.lowpass(t_m / kt, self.dt, self.cutoff)

