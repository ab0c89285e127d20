"""hdgym.reproduce.splines_study: the T3 study's pieces (the full run is its command)."""

from __future__ import annotations

import math

import pytest

from hdgym.params import preset
from hdgym.reproduce import splines_study as S
from hdgym.reproduce import tuttle_steps


def _fn(p) -> float:
    """Two-inertia small-signal frequency of k1, Hz (docs/physics.md 'The resonance trap')."""
    jm = p.motor.inertia * p.transmission.ratio ** 2
    return math.sqrt(p.compliance.stiffness * (1 / p.load.inertia + 1 / jm)) / (2 * math.pi)


def test_splines_base_moves_the_friction_and_keeps_its_steady_total():
    b = preset("tuttle-joint1")
    p = S.splines_base("tuttle-joint1")
    assert p.friction.placement == "splines"
    f = 1 - b.friction.load_coefficient
    for k in S.FRICTION_FIELDS:
        assert getattr(p.friction.output, k) == pytest.approx(getattr(b.friction.output, k) * f)
    # at steady speed the spring carries the friction F, the tooth term adds mu' F:
    # base / (1 - mu') is the bundled level again
    assert p.friction.output.coulomb / (1 - p.friction.load_coefficient) == \
        pytest.approx(b.friction.output.coulomb)


def test_splines_base_refuses_a_joint_already_moved(monkeypatch):
    monkeypatch.setattr(S, "preset", lambda n: preset(n).set("friction.placement", "splines"))
    with pytest.raises(ValueError, match="starts from the mesh presets"):
        S.splines_base("tuttle-joint1")


def test_apply_scales_sets_kb_and_moves_only_the_inertia():
    p = S.splines_base("tuttle-joint2")
    q = S.apply(p, {"x compliance.cubic": 2.0, "x hysteresis.element_strength": 0.5,
                    "motor.torque_constant": 0.03})
    assert q.compliance.cubic == pytest.approx(2 * p.compliance.cubic)
    assert q.hysteresis.element_strength == pytest.approx(
        [0.5 * w for w in p.hysteresis.element_strength])
    assert q.motor.back_emf_constant == q.motor.torque_constant == 0.03
    r = S.apply(p, {"load.inertia": 0.2})
    assert r.load.inertia == 0.2
    assert _fn(r) == pytest.approx(_fn(p), rel=1e-12)  # the preset's resonance is kept
    assert r.compliance.stiffness > 2 * p.compliance.stiffness


def test_the_rule_keeps_off_failing_points_and_the_grid_edge():
    fails = {(0, 0), (0, 1)}
    assert S._depth((4, 4), fails, (9, 9)) == 4
    assert S._depth((1, 1), fails, (9, 9)) == 1
    assert S._depth((8, 4), set(), (9, 9)) == 1  # on the edge: the unknown is next door


def test_proposed_joints_and_the_bundled_names_inside_the_block():
    assert S.proposed("tuttle-joint2", None) == preset("tuttle-joint2")
    p1 = S.proposed("tuttle-joint1")
    assert p1.friction.placement == "splines"
    assert S.SPLINES_TEXT in p1.description and S.MESH_TEXT not in p1.description
    for path in S.PROPOSED["tuttle-joint1"]:
        assert "T3 held out" in p1.sources[path]
    with S.proposed_presets():
        assert tuttle_steps.preset("tuttle-joint1") == p1
        assert tuttle_steps.preset("tuttle-joint2") == preset("tuttle-joint2")
    assert tuttle_steps.preset("tuttle-joint1") == preset("tuttle-joint1")


def test_quick_study_writes_the_scans(tmp_path):
    S.study(tmp_path, quick=True, echo=lambda s: None)
    text = (tmp_path / "study.md").read_text()
    assert "tuttle-joint1: motor.torque_constant, compliance.damping on item T2" in text
    assert "Chosen by the rule" in text and "PASS" in text
