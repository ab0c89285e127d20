"""Calibration of tuttle-joint1's K_t and damping on item T2, T3 held out.

    python -m hdgym.reproduce.calibration            # the preset's grid (195 points, ~1 min)
    python -m hdgym.reproduce.calibration --quick    # 3 x 3 points around the preset's values

Tuttle's motor constant and the joint's damping were lost in the OCR (the preset's
``[sources]``). Each grid point is the bundled preset with those two numbers set (K_b = K_t,
SI), judged by item T2's criteria alone (:func:`.tuttle_steps.joint1_steps`: the 2.8-4.0 A
steps settle within 10 % of each other near 8,000 deg/s, a jump above them, none with the
tooth friction off). The rule picks the passing point farthest (Chebyshev distance, in grid
steps) from any failing point, the points just outside the grid counting as failing;
ties go to the smaller plateau spread. After the choice, the held-out item T3 (the torque
sensor's peak at the plateau, 60-110 N m, and its mean within 10 N m of zero) is read at
every T2-passing point: how much the check depends on where in the passing region the rule
landed. Prints the map and the choice; writes nothing.
"""

from __future__ import annotations

import argparse
import itertools
from dataclasses import dataclass

import numpy as np

from hdgym.params import JointParams, preset
from hdgym.progress import bar
from hdgym.reproduce import tuttle_steps
from hdgym.reproduce.common import verdict

PRESET = "tuttle-joint1"
KT = tuple(round(0.056 + 0.001 * i, 3) for i in range(15))  # N m/A
DAMPING = tuple(float(d) for d in range(8, 33, 2))  # N m s/rad
QUICK_KT = (0.064, 0.065, 0.066)
QUICK_DAMPING = (18.0, 20.0, 22.0)


@dataclass(frozen=True)
class Point:
    """One grid point: T2's verdict and plateau spread, and T3's statistic."""

    kt: float
    damping: float
    t2: bool
    spread: float  # max/min - 1 of the 2.8-4.0 A speeds
    t3_peak: float  # largest |torque| over the plateau currents, N m (nan: no plateau)
    t3_mean: float  # largest |mean torque| over the plateau currents, N m


def joint(kt: float, damping: float) -> JointParams:
    """The bundled joint 1 with K_t (= K_b) and the compliance damping set."""
    return (preset(PRESET).set("motor.torque_constant", kt)
            .set("motor.back_emf_constant", kt).set("compliance.damping", damping))


def judge(kt: float, damping: float) -> Point:
    """T2 at one grid point, and T3's statistic from the same runs."""
    st = tuttle_steps.joint1_steps(joint(kt, damping))
    sel = (st.cur > 2.8 - 1e-9) & (st.cur < 4.0 + 1e-9)
    n = st.cur.size
    peak = mean = float("nan")
    if st.res.plateau is not None:
        a, b = st.res.plateau
        peak = float(st.runs.torque_peak[:n][a: b + 1].max())
        mean = float(np.abs(st.runs.torque_mean[:n][a: b + 1]).max())
    return Point(kt, damping, bool(st.passed), float(st.m5[sel].max() / st.m5[sel].min() - 1),
                 peak, mean)


def t3_passes(pt: Point) -> bool:
    """T3's criteria on a point's statistic."""
    return tuttle_steps.torque_peak_ok(pt.t3_peak) and tuttle_steps.torque_mean_ok(pt.t3_mean)


def choose(grid: dict[tuple[int, int], Point], shape: tuple[int, int]) -> Point | None:
    """The rule: the T2-passing point farthest from a failing one or the grid's edge."""
    fails = [ij for ij, pt in grid.items() if not pt.t2]

    def depth(ij: tuple[int, int]) -> int:
        edge = min(min(i + 1, n - i) for i, n in zip(ij, shape, strict=True))
        near = [max(abs(a - b) for a, b in zip(ij, f, strict=True)) for f in fails]
        return min([edge, *near])

    passing = [ij for ij, pt in grid.items() if pt.t2]
    if not passing:
        return None
    return grid[max(passing, key=lambda ij: (depth(ij), -grid[ij].spread))]


def scan(kts: tuple[float, ...], dampings: tuple[float, ...]
         ) -> tuple[dict[tuple[int, int], Point], Point | None]:
    """Every grid point judged, and the rule's choice."""
    points = list(itertools.product(enumerate(kts), enumerate(dampings)))
    grid = {(i, j): judge(kt, d)
            for (i, kt), (j, d) in bar(points, "calibrate tuttle-joint1", unit="point")}
    return grid, choose(grid, (len(kts), len(dampings)))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="3 x 3 points around the preset")
    args = ap.parse_args(argv)
    kts, ds = (QUICK_KT, QUICK_DAMPING) if args.quick else (KT, DAMPING)
    grid, best = scan(kts, ds)
    print("T2 over K_t (rows, N m/A) x damping (columns, N m s/rad): P passes, . fails; "
          "* T3 would pass (held out, not used by the rule)")
    print("       " + " ".join(f"{d:>4g}" for d in ds))
    for i, kt in enumerate(kts):
        print(f"{kt:.3f} " + " ".join(
            f"{('P' if grid[i, j].t2 else '.') + ('*' if t3_passes(grid[i, j]) else ' '):>4}"
            for j in range(len(ds))))
    if best is None:
        print("no grid point passes T2")
        return 1
    passing = [pt for pt in grid.values() if pt.t2]
    both = [pt for pt in passing if t3_passes(pt)]
    print(f"chosen: K_t {best.kt:g} N m/A, damping {best.damping:g} N m s/rad (T2 spread "
          f"{100 * best.spread:.1f} %); held-out T3 there: peak {best.t3_peak:.0f} N m, "
          f"mean {best.t3_mean:.1f} N m: {verdict(t3_passes(best))}")
    peaks = [pt.t3_peak for pt in passing]
    print(f"T3 at the {len(passing)} T2-passing points: {len(both)} pass; peaks "
          f"{min(peaks):.0f}-{max(peaks):.0f} N m")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
