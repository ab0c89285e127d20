"""Speed of the discrepancy workflow: diagnose a 60 s record at 1 kHz.

``bench_diagnose(quick)`` returns rows in the format of :mod:`hdgym.bench`
(name, value, unit, reference, reference_value, ratio, target, met); the
lead engineer merges them into ``results/bench.md``.
"""

from __future__ import annotations

import time

import numpy as np

from hdgym.record import Record
from hdgym.sim import Simulator

TARGET_S = 60.0


def _record(duration: float) -> tuple[Record, object, object]:
    from .cases import Case, base_for, truth_for
    from .experiments import command

    case = Case("bench", ("kinematic_error",), "slow_constant_speed", duration)
    truth = truth_for(case)
    u, tl = command(case.protocol, truth, duration, 1)
    rec = Simulator(truth).run(u, seed=1, load_torque=tl)
    return rec, truth, base_for(case, truth)


def bench_diagnose(quick: bool = False) -> list[dict]:
    """Wall time of ``diagnose`` on a 60 s, 1 kHz record with a hidden kinematic error.

    ``quick`` runs the workflow's quick settings on the same 60 s record (the
    name says so). The reference is the time of one simulation of the record.
    """
    from .workflow import diagnose

    duration = 60.0
    rec, truth, base = _record(duration)
    t0 = time.perf_counter()
    Simulator(truth, sensors=False).trajectory(np.asarray(rec.current_command))
    t_sim = time.perf_counter() - t0
    t0 = time.perf_counter()
    diag = diagnose(rec, base, quick=quick)
    value = time.perf_counter() - t0
    rows = [{
        "name": ("discrepancy diagnose, 60 s record at 1 kHz"
                 + (" (quick settings)" if quick else "")
                 + f"; found {', '.join(diag.missing_effects) or 'none'}"),
        "value": value, "unit": "s", "reference": "one simulation of the record",
        "reference_value": t_sim, "ratio": value / max(t_sim, 1e-12),
        "target": f"< {TARGET_S:g} s on the 2-core machine", "met": value < TARGET_S,
    }]
    rows.append(_bench_blind(quick))
    return rows


def _bench_blind(quick: bool) -> dict:
    """The same on a full preset: a 60 s record like the first blind kinematic-error case."""
    from hdgym.params import preset

    from .holdout import Blind, base_model
    from .workflow import diagnose

    case = Blind("tuttle-joint3", "kinematic_error", "step:0.30")
    truth = preset(case.preset)
    rec = Simulator(truth).run(case.command, 60.0, seed=1)
    t0 = time.perf_counter()
    Simulator(truth, sensors=False).trajectory(np.asarray(rec.current_command))
    t_sim = time.perf_counter() - t0
    t0 = time.perf_counter()
    diag = diagnose(rec, base_model(case, truth), quick=quick)
    value = time.perf_counter() - t0
    return {
        "name": (f"discrepancy diagnose, 60 s record of {case.name}"
                 + (" (quick settings)" if quick else "")
                 + f"; found {', '.join(diag.missing_effects) or 'none'}"),
        "value": value, "unit": "s", "reference": "one simulation of the record",
        "reference_value": t_sim, "ratio": value / max(t_sim, 1e-12),
        "target": f"< {TARGET_S:g} s on the 2-core machine", "met": value < TARGET_S,
    }


if __name__ == "__main__":
    for row in bench_diagnose(quick=False):
        print(row)
