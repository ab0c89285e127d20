"""Property tests: random drives stay finite and dissipative; bad ones are named."""

from __future__ import annotations

import hashlib
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import make_joint
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hdgym.effects import EFFECTS, flags_of
from hdgym.params import Hysteresis, Motor
from hdgym.physics import kernel
from hdgym.physics import layout as L
from hdgym.sim import Simulator

SCALES = {
    "motor.inertia": (0.3, 3.0),
    "motor.torque_constant": (0.5, 2.0),
    "compliance.stiffness": (0.5, 2.0),
    "compliance.cubic": (0.0, 3.0),
    "compliance.damping": (0.0, 5.0),
    "load.inertia": (0.2, 5.0),
    "friction.tooth_mu": (0.0, 3.0),
    "amplifier.bandwidth": (0.2, 5.0),
}


@st.composite
def drives(draw):
    p = make_joint(draw(st.sampled_from(["maxwell", "tanh"])),
                   draw(st.sampled_from(["cubic", "linear", "two_segment", "three_segment"])),
                   draw(st.sampled_from(["flexspline", "circular_spline"])))
    for path, (lo, hi) in SCALES.items():
        p = p.set(path, p.get(path) * draw(st.floats(lo, hi)))
    off = draw(st.lists(st.sampled_from(EFFECTS), max_size=4, unique=True))
    return p.without(*off)


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(p=drives(), amps=st.lists(st.floats(-50, 50), min_size=5, max_size=5),
       locked=st.booleans())
def test_random_drives_finite_and_dissipative(p, amps, locked):
    """Any valid drive, any current (far beyond the limit too): finite, E_diss never falls."""
    row = L.pack(p)[None, :]
    flags = np.array([flags_of(p.effects, locked)], dtype=np.int64)
    xs = L.initial_state(row, flags, 0.1, 0.0 if locked else None)
    bad = np.zeros(1, dtype=np.bool_)
    last = 0.0
    for k in range(300):
        u = np.array([amps[k // 60]])
        kernel.step_serial(xs, row, u, np.zeros(1), 1e-4, 10, flags, bad)
        assert np.all(np.isfinite(xs)), L.STATE_NAMES[int(np.argmin(np.isfinite(xs[0])))]
        assert xs[0, L.E_DISS] >= last - 1e-12
        last = xs[0, L.E_DISS]


@settings(max_examples=40, deadline=None)
@given(field=st.sampled_from(["inertia", "torque_constant", "back_emf_constant", "resistance"]),
       value=st.one_of(st.floats(max_value=-1e-9), st.just(math.nan), st.just(math.inf)))
def test_random_invalid_motor_named(field, value):
    if field == "back_emf_constant" and value == math.inf:
        value = -1.0
    kwargs = {"inertia": 1e-4, "torque_constant": 0.1}
    kwargs[field] = value
    with pytest.raises(ValueError, match=f"motor.{field}"):
        Motor(**kwargs)


@settings(max_examples=40, deadline=None)
@given(path=st.sampled_from(["compliance.stiffness", "load.inertia", "transmission.n",
                             "amplifier.current_limit", "friction.tooth_mu",
                             "integration.ctrl_dt", "compliance.damping"]),
       value=st.one_of(st.floats(max_value=0.0, allow_infinity=False), st.just(math.nan)))
def test_random_invalid_paths_named(path, value):
    if path in ("friction.tooth_mu", "compliance.damping") and value == 0.0:
        value = -1.0
    if path == "transmission.n" and not math.isnan(value):
        value = min(value, 1.0)
    with pytest.raises(ValueError, match=path.split(".")[-1]):
        make_joint().set(path, value)


def test_negative_slip_strength_named():
    with pytest.raises(ValueError, match=r"hysteresis.element_strength\[1\]"):
        Hysteresis(element_stiffness=(1.0, 2.0), element_strength=(0.1, -0.2))


def test_unknown_effect_named():
    with pytest.raises(ValueError, match="bogus"):
        make_joint().without("bogus")


def _trajectory_hash() -> str:
    rec = Simulator(make_joint()).run("random:3:40", 0.5, seed=11)
    h = hashlib.sha256()
    for name in rec.names:
        h.update(np.ascontiguousarray(rec.columns[name]).tobytes())
    return h.hexdigest()


def test_bit_identical_across_processes():
    here = _trajectory_hash()
    code = (f"import sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); "
            "from test_properties import _trajectory_hash; print(_trajectory_hash())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=300)
    assert out.stdout.strip().splitlines()[-1] == here
    assert _trajectory_hash() == here
