"""The ranking's Gauss-Newton start for order-line candidates (escalated horizons)."""

from __future__ import annotations

from hdgym.discrepancy import cases
from hdgym.discrepancy.problem import Problem
from hdgym.discrepancy.ranking import rank_candidates


def test_order_line_candidates_get_a_newton_start_only_when_asked():
    """With ``newton`` (the escalated horizons) an order-line candidate (kinematic error)
    carries a Gauss-Newton start from its zero-amplitude start; without it none. (A loop
    variable once shadowed the flag, so the start was never computed.)"""
    case = cases.Case("kinematic_error", ("kinematic_error",), "slow_constant_speed")
    truth = cases.truth_for(case)
    train, _ = cases.records(case, truth, 1.5)
    base = cases.base_for(case, truth)
    prob = Problem(train, base)
    with_newton = {c["name"]: c for c in rank_candidates(prob, base, None, newton=True)}
    plain = {c["name"]: c for c in rank_candidates(prob, base, None, newton=False)}
    assert with_newton["kinematic_error"]["_newton"] is not None
    assert plain["kinematic_error"]["_newton"] is None
    # only order-line candidates get one
    assert all(c["_newton"] is None for n, c in with_newton.items()
               if n not in ("kinematic_error", "position_dependent_friction"))
