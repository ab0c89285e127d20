"""hdgym.reproduce.calibration: joint 1's K_t and damping from item T2 alone, T3 held out."""

from __future__ import annotations

import pytest

from hdgym.params import preset
from hdgym.reproduce import calibration as C


def test_the_rule_picks_the_bundled_values_and_t3_holds_there(capsys) -> None:
    """On the 3 x 3 grid around the preset's values the rule (deepest T2-passing point)
    lands on the preset's K_t and damping, and the held-out T3 passes there."""
    p = preset(C.PRESET)
    assert C.main(["--quick"]) == 0
    out = capsys.readouterr().out
    assert (f"chosen: K_t {p.motor.torque_constant:g} N m/A, damping "
            f"{p.compliance.damping:g} N m s/rad") in out
    assert "PASS" in out.splitlines()[-2]


def test_choose_is_the_deepest_point_ties_to_the_smaller_spread() -> None:
    def pt(t2: bool, spread: float = 0.05) -> C.Point:
        return C.Point(0.06, 10.0, t2, spread, float("nan"), float("nan"))

    # 5 x 5, all pass: the centre is three steps from the grid's edge, every other point at
    # most two, so depth wins over its larger spread
    grid = {(i, j): pt(True) for i in range(5) for j in range(5)}
    grid[2, 2] = pt(True, spread=0.09)
    assert C.choose(grid, (5, 5)) is grid[2, 2]
    # a failing neighbour leaves the centre one step deep; (1, 1) is two from both
    grid[2, 3] = pt(False)
    grid[1, 1] = pt(True, spread=0.01)
    assert C.choose(grid, (5, 5)) is grid[1, 1]
    # nothing passes: no choice
    assert C.choose({(0, 0): pt(False)}, (1, 1)) is None
    # a tie in depth goes to the smaller plateau spread
    grid = {(i, j): pt(True, spread=0.05 + 0.01 * i) for i in range(3) for j in range(3)}
    assert C.choose(grid, (3, 3)) is grid[1, 1]


@pytest.mark.parametrize("peak,mean,ok", [(97.0, 0.1, True), (59.0, 0.0, False),
                                          (111.0, 0.0, False), (90.0, 11.0, False),
                                          (float("nan"), 0.0, False)])
def test_t3_passes_is_t3s_band(peak: float, mean: float, ok: bool) -> None:
    assert C.t3_passes(C.Point(0.065, 20.0, True, 0.08, peak, mean)) is ok
