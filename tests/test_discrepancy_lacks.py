"""What a model lacks: an effect switched off, or switched on in name only."""

from __future__ import annotations

from hdgym.discrepancy.effect import Scales
from hdgym.discrepancy.holdout import hidden_off
from hdgym.discrepancy.outcome import lacks_only_untestable
from hdgym.discrepancy.paths import get_value
from hdgym.discrepancy.registry import lacking, lacks
from hdgym.params import preset

S = Scales(torque=10.0, speed=1.0, torsion=1e-3, current=1.0)


def test_hidden_coulomb_friction_takes_the_ripple_with_it():
    """Hiding Coulomb friction on hduc20 clears its friction ripple; position-dependent
    friction stays switched on with nothing to fit, so the model lacks it too and it can be
    a candidate once Coulomb friction is named (development seed 302)."""
    full = preset("hduc20")
    assert full.friction.output.ripple and "position_dependent_friction" in full.effects
    assert lacking(full, S) == []
    base = hidden_off(full, "coulomb_friction")
    assert "position_dependent_friction" in base.effects
    assert lacking(base, S) == ["coulomb_friction", "position_dependent_friction"]
    # by the switch alone it would not read as missing
    assert lacks_only_untestable(base, {"coulomb_friction": "-"})
    assert not lacks_only_untestable(base, {"coulomb_friction": "-"}, S)


def test_a_zero_breakaway_excess_is_not_a_missing_stiction():
    """Hiding Stribeck friction zeroes the breakaway excess stiction shares; stiction keeps
    a parameter the base fit moves, so it is not lacking (and is no candidate to name in
    Stribeck friction's place)."""
    base = hidden_off(preset("hduc20"), "stribeck_friction")
    assert get_value(base, "friction.output.breakaway_excess") == 0.0
    assert not lacks(base, "stiction", S)
    assert lacks(base, "stribeck_friction", S)
    assert lacks(base.without("stiction"), "stiction", S)

