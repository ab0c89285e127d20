"""Simulator, command signals and records from simulation."""

from __future__ import annotations

import re

import numpy as np
import pytest
from conftest import make_joint

from hdgym.commands import command_signal
from hdgym.physics import layout as L
from hdgym.record import read_record
from hdgym.sim import SimulationError, Simulator


def test_run_is_deterministic_and_round_trips(tmp_path, joint):
    sim = Simulator(joint)
    a = sim.run("random:2:50", 0.5, seed=3)
    b = sim.run("random:2:50", 0.5, seed=3)
    c = sim.run("random:2:50", 0.5, seed=4)
    assert a == b
    assert not np.array_equal(a.current_command, c.current_command)
    a.to_csv(tmp_path / "run.csv")
    assert read_record(tmp_path / "run.csv") == a
    assert a.meta["locked_output"] == "false"
    assert float(a.meta["ratio"]) == joint.ratio


def test_record_rows_follow_zero_order_hold(joint):
    """Row k: state at time k*dt, command applied from then on; row 0 is the start."""
    sim = Simulator(joint, sensors=False)
    t, u, _, states = sim.trajectory("step:3", 0.2)
    rec = sim.run("step:3", 0.2)
    assert rec.time[0] == 0.0 and np.allclose(np.diff(rec.time), joint.integration.ctrl_dt)
    assert rec.motor_velocity[0] == 0.0
    np.testing.assert_array_equal(rec.motor_angle, states[:, L.TH_M])
    # re-running from a mid-record state reproduces the rest
    k = 50
    t2, _, _, s2 = sim.trajectory(u[k:], state=states[k])
    np.testing.assert_allclose(s2[:, L.TH_M], states[k:, L.TH_M], rtol=0, atol=1e-12)


def test_sensors_quantize(joint):
    rec = Simulator(joint).run("step:3", 0.3)
    step = 2 * np.pi / joint.sensors.motor_counts
    counts = rec.motor_angle / step
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    true = Simulator(joint, sensors=False).run("step:3", 0.3)
    assert np.max(np.abs(true.motor_angle - rec.motor_angle)) <= step + 1e-12


def test_locked_output_record(joint):
    rec = Simulator(joint, locked_output=True).run("sine:2:1", 1.0)
    assert not rec.has("output_angle")
    assert rec.meta["locked_output"] == "true"
    assert np.ptp(rec.output_torque) > 1.0


def test_closed_loop_tracks_reference(joint):
    class PD:
        def reset(self):
            self.n = 0

        def __call__(self, t, m):
            return 300.0 * (m["reference"] - m["output_angle"]) - 0.02 * m["motor_velocity"]

    rec = Simulator(joint).run_closed_loop(PD(), 1.5, reference=lambda t: 0.05)
    assert abs(rec.output_angle[-1] - 0.05) < 5e-3
    assert rec.has("reference")


@pytest.mark.parametrize("spec, match", [
    ("bogus:1", "unknown kind"), ("step", "takes 1"), ("step:abc", "not a number"),
    ("sine:1:nan", "not finite"), ("random:1:1e6", "cutoff"),
])
def test_bad_command_specs(spec, match):
    with pytest.raises(ValueError, match=match):
        command_signal(spec, np.arange(100) * 1e-3)


def test_nan_command_names_sample(joint):
    u = np.ones(100)
    u[17] = np.nan
    with pytest.raises(ValueError, match="sample 17"):
        Simulator(joint).run(u)


def test_divergence_is_an_error_not_nan():
    p = make_joint().set("integration.n_substeps", 1).set("compliance.stiffness", 6e9)
    with pytest.raises(SimulationError, match=r"diverged at t = .* s: state"):
        Simulator(p).run("step:6", 1.0)


def test_commands_have_requested_shape():
    t = np.arange(1000) * 1e-3
    for spec in ("step:2", "ramp:0:5", "sine:1:5", "chirp:1:1:100", "random:1:50"):
        u = command_signal(spec, t, np.random.default_rng(0))
        assert u.shape == t.shape and np.all(np.isfinite(u))
    assert np.isclose(np.std(command_signal("random:2:50", t)), 2.0)
    assert command_signal("ramp:0:5", t)[-1] == pytest.approx(5.0)


def test_record_load_column_resimulates(joint):
    """The load_torque column is the external load applied: feeding it back reproduces the run."""
    sim = Simulator(joint, sensors=False)
    a = sim.run("step:3", 0.3, load_torque="sine:20:5")
    b = sim.run(a.current_command, load_torque=a.load_torque)
    assert a == b


# --- bad arguments name themselves (issue 13 item 6) ------------------------------------------

@pytest.mark.parametrize("duration, words", [
    (float("nan"), "duration must be a finite number of seconds, got nan"),
    ("4", "duration must be a number of seconds, got '4' (str)"),
    (True, "duration must be a number of seconds"),
    (1e9, "duration 1e+09 s is 1,000,000,000,000 control periods"),
])
def test_run_names_a_bad_duration(duration, words):
    from hdgym.params import preset

    with pytest.raises(ValueError, match=re.escape(words)):
        Simulator(preset("tuttle-joint1")).run("step:1", duration)


def test_too_long_is_refused_before_allocating():
    from hdgym.params import preset
    from hdgym.sim import BYTES_PER_PERIOD, _memory_bytes

    sim = Simulator(preset("tuttle-joint1"))
    periods = _memory_bytes() // BYTES_PER_PERIOD + 10
    with pytest.raises(ValueError, match="more than this machine's"):
        sim.time(periods * sim.ctrl_dt)
