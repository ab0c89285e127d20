"""The least-squares fit of :mod:`hdgym.discrepancy.fitting` on a real comparison."""

from __future__ import annotations

import numpy as np

from hdgym.discrepancy import fitting as F
from hdgym.discrepancy.effect import FitParam
from hdgym.discrepancy.paths import get_value, set_values
from hdgym.discrepancy.problem import Problem
from hdgym.params import preset
from hdgym.sim import Simulator

PATHS = ("motor.inertia", "compliance.stiffness", "friction.input.coulomb")


def test_a_fit_does_not_depend_on_how_many_threads_difference_it(monkeypatch):
    truth = preset("tuttle-joint3")
    rec = Simulator(truth).run("step:0.30", 1.0, seed=1)
    start = set_values(truth, {k: 1.04 * get_value(truth, k) for k in PATHS})
    fps = [FitParam(k, 0.5 * get_value(truth, k), 2.0 * get_value(truth, k)) for k in PATHS]
    prob = Problem(rec, start, segment=0.1)
    fits = []
    for n in (1, 2):
        monkeypatch.setattr(F, "FD_THREADS", n)
        fits.append(F.fit(prob, start, fps, max_nfev=3, coarse=True))
    one, two = fits
    assert one.values == two.values  # bit for bit: the columns are the same evaluations
    assert one.nfev == two.nfev and one.cost == two.cost
    assert one.cost < prob.nmse(start)["mean"] / 100  # and the fit did move
    assert np.isfinite(one.cost)
