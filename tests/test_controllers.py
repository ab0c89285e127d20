"""Controllers: PID law, invalid settings, linear model, and each benchmark improvement (quick)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controllers import experiments, scenarios, tuning
from controllers.adapter import ControllerPolicy
from controllers.dob import DisturbanceObserver
from controllers.filters import notch
from controllers.ke_feedforward import KEFeedforward, KEModel, identify_ke
from controllers.pid import PID, Cascade, PositionPID
from controllers.repetitive import RepetitiveController
from hdgym.params import preset

# control.margin evaluates high-order polynomials far beyond the band of interest
pytestmark = pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")


@pytest.fixture(scope="module")
def cfg() -> dict[str, float]:
    return experiments.settings(quick=True)


# ------------------------------------------------------------------ PID law


def test_pid_limits_and_back_calculation_anti_windup() -> None:
    def run(mode: str) -> list[float]:
        pid = PID(2.0, 5.0, dt=0.01, u_min=-1.0, u_max=1.0, anti_windup=mode)
        out = [pid.update(10.0, 0.0) for _ in range(300)]  # long saturation
        out += [pid.update(0.0, 0.5) for _ in range(100)]  # then overshoot
        return out

    for mode in ("back_calculation", "clamping", "none"):
        assert max(abs(u) for u in run(mode)) <= 1.0
    # with anti-windup the output leaves saturation at once when the error flips
    assert run("back_calculation")[301] < 0.0
    assert run("clamping")[301] < 0.0
    assert run("none")[301] == 1.0


def test_pd_without_integral_keeps_no_offset_after_saturation() -> None:
    pid = PID(2.0, 0.0, 0.0, dt=0.01, u_min=-1.0, u_max=1.0)
    for _ in range(100):
        pid.update(10.0, 0.0)  # long saturation
    assert pid.update(0.0, 0.0) == 0.0  # back-calculation left no integral behind
    ctrl, _ = scenarios.motor_pid(preset("tuttle-joint3"))
    pd = ctrl.without_integral()
    assert pd.pid.ki == 0.0 and pd.pid.kp == ctrl.pid.kp and ctrl.pid.ki > 0
    assert pd is not ctrl and pd.pid is not ctrl.pid


def test_pid_filtered_derivative_and_bumpless_reset() -> None:
    dt, kd, tf = 1e-3, 0.1, 0.01
    pid = PID(0.0, 0.0, kd, dt=dt, tf=tf, derivative_on="error")
    pid.update(0.0, 0.0)
    first = pid.update(1.0, 0.0)  # unit error step
    assert first == pytest.approx(kd / (tf + dt))  # finite kick, not kd/dt
    assert pid.update(1.0, 0.0) == pytest.approx(first * tf / (tf + dt))
    # derivative on measurement: no kick on a setpoint step
    pid = PID(1.0, 0.0, kd, dt=dt, tf=tf)
    pid.update(0.0, 0.0)
    assert pid.update(1.0, 0.0) == pytest.approx(1.0)
    # bumpless reset and gain change
    pid = PID(3.0, 20.0, 0.05, dt=dt)
    pid.reset(output=0.7, setpoint=1.0, measurement=0.8)
    assert pid.update(1.0, 0.8) == pytest.approx(0.7 + 20.0 * dt * 0.2 * 0, abs=1e-9)
    before = pid.update(1.0, 0.8)
    pid.set_gains(6.0, 40.0, 0.05, setpoint=1.0, measurement=0.8)
    assert pid.update(1.0, 0.8) == pytest.approx(before + 20.0 * dt * 0.2, rel=0.05)


def test_cascade_point_to_point_settles() -> None:
    p = preset("tuttle-joint1")
    dt = p.integration.ctrl_dt
    for feedback, kpos in (("motor", 25.0), ("output", 10.0)):
        vel = PID(0.5, 10.0, dt=dt, u_min=-6.0, u_max=6.0)  # A per motor rad/s
        pos = PID(kpos, 0.0, dt=dt)  # motor rad/s per rad
        ctrl = Cascade(pos, vel, p.ratio, feedback=feedback, velocity_filter_hz=100.0)
        run = scenarios.closed_loop(p, ctrl, 2.0, scenarios.min_jerk(0.2, 0.1, 0.8))
        assert np.abs(run.error).max() < 3e-3
        assert abs(run.error[-1]) < 1e-3


# ------------------------------------------------------------------ invalid settings


@pytest.mark.parametrize("make, name", [
    (lambda: PID(-1.0), "kp"),
    (lambda: PID(1.0, -2.0), "ki"),
    (lambda: PID(1.0, kd=-0.1), "kd"),
    (lambda: PID(1.0, dt=0.0), "dt"),
    (lambda: PID(1.0, u_min=1.0, u_max=-1.0), "u_min"),
    (lambda: PID(1.0, anti_windup="magic"), "anti_windup"),
    (lambda: DisturbanceObserver(lambda t, m: 0.0, 1e-4, 0.05, 600.0, 1e-3), "bandwidth_hz"),
    (lambda: DisturbanceObserver(lambda t, m: 0.0, -1e-4, 0.05, 50.0), "inertia"),
    (lambda: RepetitiveController(lambda t, m: 0.0, 161.0, (0, 2)), "orders"),
    (lambda: RepetitiveController(lambda t, m: 0.0, 161.0, (2, -4)), "orders"),
    (lambda: RepetitiveController(lambda t, m: 0.0, 161.0, (2,), output_orders=(0,)),
     "output_orders"),
    (lambda: RepetitiveController(lambda t, m: 0.0, 161.0, (2,), gain=2.5), "gain"),
    (lambda: RepetitiveController(lambda t, m: 0.0, 161.0, (2,), gain=-0.1), "gain"),
    (lambda: KEModel(orders=(0.0,), cos=(0.0,), sin=(0.0,)), "orders"),
    (lambda: notch(600.0, 1e-3), "freq_hz"),
    (lambda: PositionPID(PID(1.0), -3.0), "ratio"),
    (lambda: Cascade(PID(1.0), PID(1.0), 161.0, velocity_filter_hz=900.0),
     "velocity_filter_hz"),
    (lambda: tuning.design_pid(tuning.output(tuning.linearize(preset("tuttle-joint1")),
                                             "motor_angle"), 5.0, 95.0), "phase_margin_deg"),
])
def test_invalid_settings_name_the_setting(make, name) -> None:
    with pytest.raises(ValueError, match=name):
        make()


def test_identify_ke_rejects_bad_orders_and_short_records() -> None:
    class Rec:
        time = np.arange(1000) * 1e-3
        motor_angle = np.linspace(0, 3.0, 1000)
        output_angle = motor_angle / 161.0
        meta = {"ratio": "161.0"}

    with pytest.raises(ValueError, match="orders"):
        identify_ke(Rec(), (2, 0))
    with pytest.raises(ValueError, match="revolutions"):
        identify_ke(Rec(), (2,))


def test_identify_ke_separates_wind_up_with_the_torque_column() -> None:
    class Rec:
        time = np.arange(20000) * 1e-3
        motor_angle = np.linspace(0, 40 * np.pi, 20000)
        output_torque = 3.0 + np.sin(time / 3.0)  # slowly varying friction, N m
        output_angle = (motor_angle / 80.0 - 2e-4 * np.sin(2 * motor_angle + 0.3)
                        - 1e-4 * np.cos(4 * motor_angle) - output_torque / 3000.0)
        meta = {"ratio": "80"}

    m = identify_ke(Rec(), (2, 4), torque=True)
    assert m.compliance == pytest.approx(1 / 3000.0, rel=0.02)
    assert m.amplitudes()[2.0] == pytest.approx(2e-4, rel=0.02)
    assert m.amplitudes()[4.0] == pytest.approx(1e-4, rel=0.02)
    assert m.residual_rms < 1e-6


# ------------------------------------------------------------------ tuning


@pytest.mark.parametrize("name", ["tuttle-joint1", "tuttle-joint3"])
def test_linear_model_matches_simulated_response(name: str) -> None:
    """Bode of the linear model vs H1 through the Simulator, below the resonance: 1 dB, 5 deg."""
    p = tuning.small_signal_joint(preset(name))
    sys = tuning.linearize(p)
    assert sys.noutputs == len(tuning.OUTPUTS) and sys.ninputs == 1
    fmax = 0.6 * min(tuning.resonance_hz(p),
                     math.sqrt(tuning.stiffness(p) / p.load.inertia) / (2 * math.pi))
    for ch in ("motor_velocity", "output_torque"):
        f, h, _ = tuning.simulated_response(p, ch, duration=40.0)
        m = tuning.model_response(sys, ch, f, dt=p.integration.ctrl_dt)
        k = (f >= 1.0) & (f <= fmax)
        assert k.sum() > 20
        db = 20 * np.log10(np.abs(h[k]) / np.abs(m[k]))
        deg = np.degrees(np.angle(h[k] / m[k]))
        assert np.abs(db).max() < 1.0, (ch, np.abs(db).max())
        assert np.abs(deg).max() < 5.0, (ch, np.abs(deg).max())


def test_design_pid_reaches_phase_margin() -> None:
    p = preset("tuttle-joint1")
    plant = tuning.output(tuning.linearize(p), "motor_angle")
    d = tuning.design_pid(plant, 8.0, 50.0, delay=1e-3)
    assert d.phase_margin_deg == pytest.approx(50.0, abs=0.5)
    assert d.crossover_hz == pytest.approx(8.0, rel=0.02)
    assert d.kp > 0 and d.ki > 0 and d.kd > 0
    ctrl, design = scenarios.motor_pid(p)
    assert design.phase_margin_deg >= 44.0 and design.gain_margin_db >= 6.0


def test_loop_margins_agree_with_python_control_without_overflow() -> None:
    """On a low-order loop both methods work and agree; on the high-order design loop
    the frequency-response margins raise no overflow warning."""
    import warnings

    import control

    s = control.tf("s")
    loop = 40.0 / (s * (s + 2.0) * (s + 10.0))
    gm, pm, wcg, wcp = control.margin(loop)
    got = tuning.loop_margins(loop, wcp)
    assert got == pytest.approx((gm, pm, wcg, wcp), rel=1e-6)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        _, design = scenarios.motor_pid(preset("tuttle-joint1"))
    assert design.phase_margin_deg == pytest.approx(45.0, abs=1.0)


# ------------------------------------------------------------------ improvements


@pytest.fixture(scope="module")
def tracking(cfg) -> dict[str, dict]:
    return {name: experiments.tracking(preset(name), cfg, experiments.PRIMARY[name])
            for name in experiments.JOINTS}


@pytest.mark.parametrize("name", experiments.JOINTS)
def test_ke_feedforward_from_identified_model(tracking, name: str) -> None:
    tr = tracking[name]
    p = preset(name)
    # the model came from a record; its dominant line matches the drive's
    amps = tr["model"].amplitudes()
    true = {h.order * p.transmission.port_factor(h.port): h.amplitude
            for h in p.kinematic_error.harmonics}
    dominant = max(true, key=true.get)
    assert amps[min(amps, key=lambda o: abs(o - dominant))] == pytest.approx(true[dominant],
                                                                            rel=0.1)
    # the mesh friction identified from the same record: the preset's level at that speed
    # (Coulomb + viscous; the tooth term adds a little) and its once-per-output-rev ripple
    fo = p.friction.output
    w_out = tr["output_speed"]
    mesh = tr["mesh_friction"]
    assert p.friction.placement == "mesh"
    # (an identification from a record: a per cent below the base level is its error)
    base = fo.coulomb + fo.viscous * w_out
    assert 0.97 * base <= mesh.level <= 1.3 * base, (mesh.level, base)
    ripple = math.hypot(mesh.cos[0], mesh.sin[0])
    assert ripple == pytest.approx(fo.ripple[0].amplitude, rel=0.3)
    assert tr["reduction"]["PID + KE feedforward"] >= experiments.KE_TARGET
    # the mesh friction's term is what the sensor-only feedforward misses
    assert (tr["reduction"]["PID + KE feedforward"]
            >= tr["reduction"]["PID + KE ff., sensor torque only"] + 15.0)


def test_mesh_friction_is_not_found_where_the_sensor_reads_the_friction(cfg) -> None:
    """With the friction between output and ground the torque sensor carries it:
    the identification reports (almost) none in the mesh."""
    p = preset("tuttle-joint3").set("friction.placement", "output")
    d = experiments.tracking_design(p, cfg, 1.0)
    assert abs(d.mesh_friction.level) < 0.05 * p.friction.output.coulomb


def test_identify_mesh_friction_recovers_a_known_level() -> None:
    """Synthetic record from the motor's torque balance with a known mesh friction."""
    from controllers.ke_feedforward import identify_mesh_friction

    ratio, kt, jm = 80.0, 0.03, 5e-6
    model = KEModel(orders=(2.0, 4.0), cos=(1e-4, 0.0), sin=(2e-4, 1.5e-4))
    t = np.arange(60000) * 1e-3
    th = 2 * np.pi * t + 1e-3 * np.sin(9.0 * t)  # near constant speed, motor wobble
    th_o = th / ratio
    level, ripple = 0.3, 0.08
    f_mesh = level + ripple * np.sin(th_o)
    tk = 0.01 * np.sin(4 * th)  # what the sensor reads (output inertia torque)
    slope = np.array([model.slope(x) for x in th])
    acc = np.gradient(np.gradient(th, t), t)
    current = (0.002 + jm * acc + (1 / ratio - slope) * (tk + f_mesh)) / kt

    class Rec:
        time = t
        motor_angle = th
        output_angle = th_o
        columns = {"current_command": current, "output_torque": tk}
        meta = {"ratio": str(ratio)}

    mf = identify_mesh_friction(Rec(), model, torque_constant=kt, motor_inertia=jm,
                                output_orders=(1.0,))
    assert mf.level == pytest.approx(level, rel=0.02)
    assert mf.sin[0] == pytest.approx(ripple, rel=0.05)
    assert abs(mf.cos[0]) < 0.05 * ripple
    with pytest.raises(ValueError, match="output_torque"):
        Rec.columns = {"current_command": current}
        identify_mesh_friction(Rec(), model, torque_constant=kt, motor_inertia=jm)


@pytest.mark.parametrize("name", experiments.JOINTS)
def test_repetitive_control_converges_and_survives_speed_change(tracking, name: str) -> None:
    tr = tracking[name]
    assert tr["reduction"]["PID + repetitive"] >= experiments.RC_TARGET
    conv = np.array(tr["convergence"])
    assert conv[-1, 1] < 0.2 * conv[2, 1] or conv[2, 1] < 0.2 * conv[2, 2]  # it learnt
    sweep = tr["sweep_rms"]
    assert sweep["PID + repetitive (learnt)"] < 0.5 * sweep["PID"]


def test_repetitive_stability_condition_is_checked() -> None:
    rc = RepetitiveController(lambda t, m: 0.0, 161.0, (2, 4), gain=0.5)
    assert rc.check_stability(lambda w: 1.0, [1.0, 10.0]) == pytest.approx(0.5)
    with pytest.raises(ValueError, match="gain"):
        rc.check_stability(lambda w: -1.0, [1.0])  # 180 deg out of phase: diverges


@pytest.mark.parametrize("name", experiments.JOINTS)
def test_dob_meets_the_load_step_target(cfg, name: str) -> None:
    """Half the PID's peak, or within DOB_HELD_FACTOR of the motor-held swing where that
    is higher (tuttle-joint1: half the PID's peak lies below the swing), and a faster
    recovery; the swing is a lower bound for every motor-side loop."""
    res = experiments.load_step(preset(name), cfg)
    m = res["metrics"]
    assert res["met"], (res["reduction"], res["held"], m)
    assert m["PD + DOB"]["peak"] <= res["peak_target"]
    assert m["PD + DOB"]["recovery"] < m["PID"]["recovery"]
    for k in m:  # the bound holds
        assert m[k]["peak"] >= 0.98 * res["held"], k
    if res["held"] < 0.5 * m["PID"]["peak"]:  # reachable: the brief's target itself
        assert res["reduction"] >= experiments.DOB_TARGET
    # with the PID's integral kept inside the DOB the loop hunts and never recovers as fast
    assert m["PD + DOB"]["recovery"] < 0.5 * m["PID + DOB"]["recovery"]
    # no limit cycle: the current settles after the step
    u = np.asarray(res["runs"]["PD + DOB"].record.columns["current_command"])
    assert u[-500:].std() < 0.02 * preset(name).amplifier.current_limit


def test_dob_estimates_a_constant_disturbance() -> None:
    dt, j, kt = 1e-3, 1e-4, 0.05
    dob = DisturbanceObserver(lambda t, m: 0.0, j, kt, 30.0, dt)
    th = w = 0.0
    d = 0.4  # A
    for _ in range(400):  # free rigid motor pushed by the disturbance only
        dob.update(th)
        w += dt * kt * d / j
        th += dt * w
    assert dob.update(th) == pytest.approx(d, rel=0.02)


# ------------------------------------------------------------------ adapter


def test_controller_policy_on_env() -> None:
    gym = pytest.importorskip("gymnasium")
    import hdgym  # noqa: F401  (registers the envs)

    env = gym.make("HarmonicDriveJoint-v0", preset="tuttle-joint1", reference="point_to_point")
    ctrl, _ = scenarios.motor_pid(preset("tuttle-joint1"))
    policy = ControllerPolicy.from_env(env, ctrl)
    obs, info = env.reset(seed=3)
    policy.reset()
    m = policy.measurement(obs, info)
    assert m["motor_angle"] == pytest.approx(info["motor_angle"], abs=2e-3)
    errs = []
    for _ in range(2000):
        obs, _, term, trunc, info = env.step(policy(obs, info))
        errs.append(info["tracking_error"])
        if term or trunc:
            break
    assert not term
    assert np.max(np.abs(errs[-100:])) < 1e-3


def test_ke_feedforward_wraps_reference() -> None:
    model = KEModel(orders=(2.0,), cos=(0.0,), sin=(1e-4,))
    seen = {}

    def inner(t, m):
        seen.update(m)
        return 0.0

    ff = KEFeedforward(inner, model, 100.0)
    ff(0.0, {"reference": 0.01, "motor_angle": 1.0, "output_torque": 0.0})
    # reference + theta_ke at the WG angle that puts the output there (fixed point)
    assert seen["reference"] == pytest.approx(0.01 + model.scalar(100.0 * seen["reference"]),
                                              abs=1e-6)
    assert seen["reference"] - 0.01 == pytest.approx(ff.correction(0.01))
