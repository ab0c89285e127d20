"""Shared fixtures: a joint with every effect switched on, built in code."""

from __future__ import annotations

import pytest

from hdgym.params import (
    Amplifier,
    Compliance,
    Friction,
    FrictionSide,
    Harmonic,
    Hysteresis,
    JointParams,
    KinematicError,
    Load,
    Motor,
    Ripple,
    Transmission,
)


def make_joint(hysteresis_model: str = "maxwell", compliance_model: str = "cubic",
               grounded: str = "flexspline") -> JointParams:
    """A Tuttle-joint-1-like drive with every effect in use (values illustrative)."""
    hyst = (Hysteresis(element_stiffness=(2e4, 1e4, 5e3), element_strength=(0.4, 0.8, 1.2))
            if hysteresis_model == "maxwell" else Hysteresis(model="tanh", width=1.0, shape=2e3))
    comp = {
        "cubic": Compliance(stiffness=6e4, cubic=3e9, damping=2.0),
        "linear": Compliance(stiffness=6e4, model="linear", damping=2.0),
        "two_segment": Compliance(stiffness=4e4, model="two_segment", knee=2e-4,
                                  extra_stiffness=3e4, damping=2.0),
        "three_segment": Compliance(stiffness=4e4, model="three_segment",
                                    segment_torques=(10.0, 40.0), segment_stiffness=(6e4, 9e4),
                                    damping=2.0),
    }[compliance_model]
    return JointParams(
        motor=Motor(inertia=2.2e-4, torque_constant=0.09, back_emf_constant=0.09, resistance=1.2),
        transmission=Transmission(n=160, grounded=grounded),
        compliance=comp,
        load=Load(inertia=1.0, gravity=2.0),
        amplifier=Amplifier(current_limit=6.0, voltage_limit=24.0, bandwidth=800.0),
        hysteresis=hyst,
        friction=Friction(
            input=FrictionSide(coulomb=0.05, breakaway=0.08, stribeck_velocity=2.0, viscous=1e-3,
                               cubic=-1e-9, ripple=(Ripple(order=2, amplitude=0.01),)),
            output=FrictionSide(coulomb=2.0, breakaway=3.0, stribeck_velocity=0.05, viscous=1.0,
                                ripple=(Ripple(order=1, amplitude=0.5, frame="output",
                                               phase=0.3),)),
            tooth_mu=0.15),
        kinematic_error=KinematicError(harmonics=(
            Harmonic(order=2, amplitude=3.0e-4),
            Harmonic(order=2, amplitude=0.8e-4, port="flexspline", phase=1.0),
            Harmonic(order=4, amplitude=1.2e-4, phase=0.5))),
        name="test-joint",
    )


@pytest.fixture
def joint() -> JointParams:
    return make_joint()
