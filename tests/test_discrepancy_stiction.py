"""Stiction in the hold-out cases and the workflow: what a case hides, where stiction can be
seen, and where the record's friction levels go when the sensor does not read a side."""

from __future__ import annotations

import pytest

from hdgym.discrepancy import holdout
from hdgym.discrepancy.effect import Scales
from hdgym.discrepancy.registry import REGISTRY
from hdgym.params import preset


def test_holdout_stiction_truth_has_no_stribeck_friction() -> None:
    """Beside Stribeck friction, hidden stiction is only a breakaway excess the base model's
    own Stribeck friction fits; a hold-out stiction case is made without it, keeping the
    preset's breakaway, and its base model holds no static level at all."""
    case = next(c for c in holdout.holdout_cases(134)
                if c.preset == "tuttle-joint3" and c.hidden == "stiction")
    truth = holdout.case_truth(case)
    p = preset(case.preset)
    assert "stribeck_friction" in p.effects
    assert "stribeck_friction" not in truth.effects and "stiction" in truth.effects
    assert truth.friction.output.breakaway == p.friction.output.breakaway
    base = holdout.base_model(case, truth)
    assert not {"stiction", "stribeck_friction"} & set(base.effects)
    assert base.friction.output.breakaway == base.friction.output.coulomb
    train, _ = holdout.records(case, truth)
    size, noise = holdout.effect_size(case, truth, train)
    assert size > holdout.PRESENT * noise


def test_blind_and_other_cases_keep_the_preset() -> None:
    blind = next(c for c in holdout.BLIND if c.hidden == "stiction")
    assert holdout.case_truth(blind) == preset(blind.preset)
    other = next(c for c in holdout.holdout_cases(134) if c.hidden == "stribeck_friction")
    assert holdout.case_truth(other) == preset(other.preset)


@pytest.mark.parametrize(("moving", "standstills", "reversals", "seen"),
                         [(0.5, 1, 2, True), (0.1, 2, 2, True), (0.01, 2, 2, False),
                          (0.5, 0, 2, True), (0.5, 0, 0, False)])
def test_stiction_is_seen_on_a_mostly_stuck_record(moving: float, standstills: int,
                                                   reversals: int, seen: bool) -> None:
    """Stiction's evidence is its breakaways: a joint its friction holds most of the record
    (moving in 2-20 % of it) shows them best, as it shows Coulomb friction; a moving joint
    shows them at its reversals (it is held there) or standstills, not on a run one way."""
    s = Scales(torque=1.0, speed=1.0, torsion=1e-3, current=1.0, moving=moving,
               standstills=standstills, reversals=reversals)
    assert REGISTRY["stiction"].testable(s) is seen


def test_mesh_friction_levels_go_to_the_output_side() -> None:
    """With the output friction at the mesh (Tuttle's joints) the flexspline's torque sensor
    does not read it: the motor-side reading holds both sides and sets the output side's
    levels (output-referred, less the motor side's own), not the motor side's."""
    truth = preset("tuttle-joint3")
    assert truth.friction.placement == "mesh"
    base = holdout.hidden_off(truth, "stiction")
    fi, fo, n = base.friction.input, truth.friction.output, base.ratio
    static = fi.breakaway + fo.breakaway / n
    running = fi.coulomb + fo.coulomb / n
    s = Scales(torque=1.0, speed=1.0, torsion=1e-3, current=1.0,
               static=(("input", static, running), ("output", 0.04, 0.0)))
    on = REGISTRY["stiction"].switch_on(base, s)
    assert on.friction.output.coulomb == pytest.approx(fo.coulomb)
    assert on.friction.output.breakaway == pytest.approx(fo.breakaway)
    assert on.friction.input.coulomb == fi.coulomb  # the reading says nothing of it alone


def test_stiction_starts_from_the_read_and_the_fitted_running_level() -> None:
    """The record's running level is a least-squares reading the speed and inertia terms
    share; stiction also starts from the fitted Coulomb level, with the excess up to the
    largest torque held."""
    base = holdout.hidden_off(preset("wave-drive-50"), "stiction")
    fo = base.friction.output
    s = Scales(torque=1.0, speed=1.0, torsion=1e-3, current=1.0,
               static=(("output", 1.5 * fo.coulomb, 1.2 * fo.coulomb),))
    eff = REGISTRY["stiction"]
    assert eff.form_names() == (None, "kept_running")
    read, kept = (eff.switch_on(base, s, f).friction.output for f in eff.form_names())
    assert read.coulomb == pytest.approx(1.2 * fo.coulomb)
    assert read.breakaway == pytest.approx(1.5 * fo.coulomb)
    assert kept.coulomb == fo.coulomb
    assert kept.breakaway == pytest.approx(1.5 * fo.coulomb)
