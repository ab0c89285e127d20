"""The compiled step against its numpy reference, energy, dissipation, convergence."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import make_joint

from hdgym.effects import DISSIPATIVE, EFFECTS, flags_of
from hdgym.params import preset
from hdgym.physics import kernel, lanes, reference
from hdgym.physics import layout as L


def _batch(params_list, locked=False, motor_angle=0.3):
    ps = np.stack([L.pack(p) for p in params_list])
    flags = np.array([flags_of(p.effects, locked) for p in params_list], dtype=np.int64)
    xs = L.initial_state(ps, flags, motor_angle, 0.0 if locked else None)
    return xs, ps, flags


def _run_both(params_list, current, steps, locked=False, n_sub=10, dt=1e-4, t_ext=0.0):
    xs, ps, flags = _batch(params_list, locked)
    n = len(params_list)
    xk = xs.copy()
    xr = xs.copy()
    bad = np.zeros(n, dtype=np.bool_)
    for k in range(steps):
        u = np.full(n, current(k))
        te = np.full(n, t_ext)
        kernel.step_serial(xk, ps, u, te, dt, n_sub, flags, bad)
        xr = reference.step(xr, ps, u, te, dt, n_sub, flags)
    return xk, xr


@pytest.mark.parametrize("hyst", ["maxwell", "tanh"])
@pytest.mark.parametrize("comp", ["cubic", "two_segment", "three_segment", "linear"])
def test_kernel_matches_reference(hyst, comp):
    joints = [make_joint(hyst, comp), make_joint(hyst, comp, grounded="circular_spline"),
              make_joint(hyst, comp).without("stribeck_friction", "stiction"),
              make_joint(hyst, comp).without(*EFFECTS)]
    xk, xr = _run_both(joints, lambda k: 4.0 * np.sin(0.02 * k) + 1.0, 400)
    scale = np.maximum(np.abs(xr), 1.0)
    assert np.all(np.isfinite(xk))
    np.testing.assert_allclose(xk / scale, xr / scale, rtol=0, atol=1e-9)


def test_kernel_matches_reference_locked(joint):
    xk, xr = _run_both([joint], lambda k: 2.0 * np.sin(0.05 * k), 300, locked=True)
    np.testing.assert_allclose(xk, xr, rtol=1e-9, atol=1e-12)
    assert xk[0, L.W_O] == 0.0 and xk[0, L.TH_O] == 0.0


def test_parallel_equals_serial(joint):
    xs, ps, flags = _batch([joint] * 8)
    ps[:, L.K1] *= np.linspace(0.8, 1.2, 8)
    a, b = xs.copy(), xs.copy()
    bad = np.zeros(8, dtype=np.bool_)
    u = np.linspace(1, 5, 8)
    z = np.zeros(8)
    for _ in range(50):
        kernel.step_serial(a, ps, u, z, 1e-4, 10, flags, bad)
        kernel.step_parallel(b, ps, u, z, 1e-4, 10, flags, bad)
    assert np.array_equal(a, b)


def test_energy_conserved_without_dissipation(joint):
    """All dissipative effects off, no damping: energy drift stays small over 10 s."""
    p = joint.without(*DISSIPATIVE).set("compliance.damping", 0.0).set("load.gravity", 0.0)
    xs, ps, flags = _batch([p])
    # wind the spring up and let it ring, with the motor spinning through the KE
    xs[:, L.W_M] = 60.0
    xs[:, L.TH_O] -= 1e-3
    e0 = reference.mechanical_energy(xs, ps, flags)[0]
    bad = np.zeros(1, dtype=np.bool_)
    zeros = np.zeros(1)
    drift = []
    for _ in range(10_000):  # 10 s at 1 ms
        kernel.step_serial(xs, ps, zeros, zeros, 1e-4, 10, flags, bad)
        drift.append(reference.mechanical_energy(xs, ps, flags)[0] - e0)
    assert not bad.any()
    assert max(abs(d) for d in drift) < 0.01 * e0, (e0, max(drift), min(drift))
    assert abs(drift[-1]) < 0.005 * e0


def test_dissipation_never_negative_and_energy_balance(joint):
    """Every effect on: dissipated energy never decreases and the balance closes."""
    xs, ps, flags = _batch([joint])
    e0 = reference.mechanical_energy(xs, ps, flags)[0]
    bad = np.zeros(1, dtype=np.bool_)
    rng = np.random.default_rng(1)
    last = 0.0
    for k in range(4000):
        u = np.array([6.0 * np.sin(0.003 * k) + rng.normal(0, 1)])
        kernel.step_serial(xs, ps, u, np.zeros(1), 1e-4, 10, flags, bad)
        assert xs[0, L.E_DISS] >= last - 1e-15
        last = xs[0, L.E_DISS]
    e = reference.mechanical_energy(xs, ps, flags)[0]
    inflow = xs[0, L.W_MOTOR] + xs[0, L.W_LOAD]
    assert last > 0
    # closes to a few percent of the energy that went through the joint
    assert abs(e - e0 + last - inflow) < 0.03 * (abs(inflow) + last)


def test_substep_halving_converges(joint):
    """A non-resonant trajectory changes little when the substep is halved."""
    p = joint.without("stiction", "stribeck_friction")

    def run(n_sub):
        xs, ps, flags = _batch([p])
        bad = np.zeros(1, dtype=np.bool_)
        out = []
        for k in range(500):
            u = np.array([1.5 + 0.5 * np.sin(0.01 * k)])
            kernel.step_serial(xs, ps, u, np.zeros(1), 1e-3 / n_sub, n_sub, flags, bad)
            out.append(xs[0, [L.TH_M, L.TH_O]].copy())
        return np.array(out)

    a, b = run(10), run(20)
    err = np.max(np.abs(a - b), axis=0) / np.max(np.abs(b), axis=0)
    assert np.all(err < 2e-3), err


def test_divergence_flagged():
    p = make_joint().set("integration.n_substeps", 1).set("compliance.damping", 0.0)
    xs, ps, flags = _batch([p.without(*DISSIPATIVE)])
    ps[:, L.K1] *= 1e6  # far too stiff for the step
    bad = np.zeros(1, dtype=np.bool_)
    for _ in range(200):
        kernel.step_serial(xs, ps, np.ones(1), np.zeros(1), 1e-3, 1, flags, bad)
        if bad.any():
            break
    assert bad.any()


def test_stiction_holds_below_breakaway(joint):
    """With the output locked and a current below breakaway the motor does not move."""
    xs, ps, flags = _batch([joint.without("kinematic_error", "hysteresis")])
    bad = np.zeros(1, dtype=np.bool_)
    th0 = xs[0, L.TH_M]
    small = 0.5 * joint.friction.input.breakaway / joint.motor.torque_constant
    for _ in range(200):
        kernel.step_serial(xs, ps, np.array([small]), np.zeros(1), 1e-4, 10, flags, bad)
    # the motor winds the spring but output friction (breakaway 3 N m) holds the output
    assert xs[0, L.W_O] == 0.0
    assert abs(xs[0, L.TH_M] - th0) < 1e-2


# ---------------------------------------------------------------- SIMD lanes


def _all_models(locked=False):
    joints = []
    for hyst in ("maxwell", "tanh"):
        for comp in ("cubic", "two_segment", "three_segment", "linear"):
            joints += [make_joint(hyst, comp), make_joint(hyst, comp, grounded="circular_spline"),
                       make_joint(hyst, comp).without("stribeck_friction", "stiction"),
                       make_joint(hyst, comp).without(*EFFECTS)]
    return _batch(joints, locked)


def _run_lanes(xs, ps, flags, current, steps, n_sub=10, dt=1e-4, parallel=False):
    n = xs.shape[0]
    out = xs.copy()
    lb = lanes.LaneBatch(out, ps, flags, dt, parallel=parallel)
    bad = np.zeros(n, dtype=np.bool_)
    for k in range(steps):
        lb.step(np.full(n, current(k)), np.zeros(n), n_sub, out, bad)
    return out, bad


def test_lanes_match_reference():
    """Every compliance and hysteresis model, both groundings, effects on and off; the
    batch (32 envs) also leaves spare lanes in its block."""
    xs, ps, flags = _all_models()
    current = lambda k: 4.0 * np.sin(0.02 * k) + 1.0  # noqa: E731
    xl, bad = _run_lanes(xs, ps, flags, current, 400)
    xr = xs.copy()
    for k in range(400):
        u = np.full(len(xs), current(k))
        xr = reference.step(xr, ps, u, np.zeros(len(xs)), 1e-4, 10, flags)
    scale = np.maximum(np.abs(xr), 1.0)
    assert not bad.any()
    np.testing.assert_allclose(xl / scale, xr / scale, rtol=0, atol=1e-9)


def test_lanes_match_kernel_locked():
    """Locked output, every model: the lanes agree with the one-env kernel. The motor
    sticks for long spells here, where the two round the kinematic error differently;
    the tanh model's reversal deadband keeps that rounding from restarting its loop."""
    xs, ps, flags = _all_models(locked=True)
    current = lambda k: 2.0 * np.sin(0.05 * k)  # noqa: E731
    xl, _ = _run_lanes(xs, ps, flags, current, 300)
    xk = xs.copy()
    bad = np.zeros(len(xs), dtype=np.bool_)
    for k in range(300):
        kernel.step_serial(xk, ps, np.full(len(xs), current(k)), np.zeros(len(xs)), 1e-4, 10,
                           flags, bad)
    np.testing.assert_allclose(xl, xk, rtol=1e-9, atol=1e-12)
    assert np.all(xl[:, L.W_O] == 0.0)


def test_lanes_parallel_equals_serial_and_padding():
    """Threads change nothing, and an env's result does not depend on its block mates."""
    xs, ps, flags = _batch([make_joint()] * 70)  # two blocks, the second mostly spare
    ps[:, L.K1] *= np.linspace(0.8, 1.2, 70)
    current = lambda k: 3.0 + np.sin(0.01 * k)  # noqa: E731
    a, _ = _run_lanes(xs, ps, flags, current, 50)
    b, _ = _run_lanes(xs, ps, flags, current, 50, parallel=True)
    assert np.array_equal(a, b)
    alone, _ = _run_lanes(xs[67:68], ps[67:68], flags[67:68], current, 50)
    assert np.array_equal(alone[0], a[67])


def test_lane_result_independent_of_its_place_in_the_block():
    """Bit for bit: the middle env of three (each with its own output inertia) equals the
    same env alone, through the fast run-up where the phase increments pass 0.05 rad (the
    vector body and the scalar remainder of a loop must round alike: no fused contraction)."""
    xs, ps, flags = _batch([preset("tuttle-joint1")] * 3)
    ps[:, L.J_O] *= np.array([0.9, 1.0, 1.1])
    current = lambda k: 6.0  # noqa: E731
    three, _ = _run_lanes(xs, ps, flags, current, 300)
    alone, _ = _run_lanes(xs[1:2], ps[1:2], flags[1:2], current, 300)
    assert np.array_equal(alone[0], three[1])


def test_lanes_coarse_substeps():
    """Phase increments beyond the Taylor range (1 substep per 1 ms at speed) take the
    exact sin/cos path."""
    p = make_joint().without("stiction", "stribeck_friction")
    xs, ps, flags = _batch([p])
    xs[:, L.W_M] = 300.0  # KE order 4 at 300 rad/s: 1.2 rad per 1 ms substep
    xr = xs.copy()
    xl, bad = _run_lanes(xs, ps, flags, lambda k: 2.0, 300, n_sub=1, dt=1e-3)
    for _ in range(300):
        xr = reference.step(xr, ps, np.full(1, 2.0), np.zeros(1), 1e-3, 1, flags)
    assert not bad.any()
    scale = np.maximum(np.abs(xr), 1.0)
    np.testing.assert_allclose(xl / scale, xr / scale, rtol=0, atol=1e-9)


def test_lanes_phases_stay_exact():
    """The rotated phases track sin/cos of the angles, and are recomputed exactly every
    RESYNC substeps."""
    xs, ps, flags = _batch([make_joint()])
    out = xs.copy()
    lb = lanes.LaneBatch(out, ps, flags, 1e-4)
    bad = np.zeros(1, dtype=np.bool_)
    w = lb.W[0].reshape(lanes.N_FIELDS, lanes.BLOCK)
    n_ke = int(ps[0, L.NKE])

    def phase_error():
        a = ps[0, L.KE_ORD:L.KE_ORD + n_ke] * out[0, L.TH_M] + ps[0, L.KE_PH:L.KE_PH + n_ke]
        s = w[lanes.SIN + lanes.P_KE:lanes.SIN + lanes.P_KE + n_ke, 0]
        c = w[lanes.COS + lanes.P_KE:lanes.COS + lanes.P_KE + n_ke, 0]
        return max(np.max(np.abs(s - np.sin(a))), np.max(np.abs(c - np.cos(a))))

    steps = lanes.RESYNC // 10
    for _ in range(steps - 1):
        lb.step(np.full(1, 3.0), np.zeros(1), 10, out, bad)
    assert w[lanes.COUNT, 0] == lanes.RESYNC - 10
    assert 0 < phase_error() < 1e-9  # rotated, so not bit-exact, but close
    lb.step(np.full(1, 3.0), np.zeros(1), 10, out, bad)
    lb.step(np.full(1, 3.0), np.zeros(1), 10, out, bad)  # resynced at the start of this one
    assert w[lanes.COUNT, 0] == 10
    assert phase_error() < 1e-13


def test_lanes_reject_bad_shapes():
    xs, ps, flags = _batch([make_joint()] * 3)
    lb = lanes.LaneBatch(xs.copy(), ps, flags, 1e-4)
    bad = np.zeros(3, dtype=np.bool_)
    with pytest.raises(ValueError, match="i_cmd"):
        lb.step(np.zeros(2), np.zeros(3), 10, xs, bad)
    with pytest.raises(ValueError, match="xs"):
        lb.step(np.zeros(3), np.zeros(3), 10, xs[:2], bad)
    with pytest.raises(ValueError, match="n_sub"):
        lb.step(np.zeros(3), np.zeros(3), 0, xs, bad)
    with pytest.raises(ValueError, match="idx"):
        lb.load(xs, ps, flags, [3])
    with pytest.raises(ValueError, match="dt"):
        lanes.LaneBatch(xs, ps, flags, 0.0)


def test_lanes_flag_a_diverged_env_and_leave_the_others():
    xs, ps, flags = _batch([make_joint()] * 3)
    xs[1, L.W_M] = np.nan
    xs[2, L.W_O] = np.inf
    out, bad = _run_lanes(xs, ps, flags, lambda k: 2.0, 3)
    assert list(bad) == [False, True, True]
    assert np.all(np.isfinite(out[0]))


# ---------------------------------------------------------------- every effect, three ways


def _effect_table() -> list[tuple[str, object, bool]]:
    """(label, joint, locked output): every effect alone and every effect left out, each
    compliance and hysteresis model, both groundings, the three friction placements (eq. 8)."""
    base = make_joint()
    mesh = base.set("friction.placement", "mesh")
    splines = base.set("friction.placement", "splines")
    rows = [("all effects", base, False), ("no effects", base.without(*EFFECTS), False),
            ("all effects, mesh friction", mesh, False),
            ("all effects, locked", base, True), ("all effects, mesh friction, locked", mesh, True),
            ("circular spline grounded, mesh friction",
             make_joint(grounded="circular_spline").set("friction.placement", "mesh"), False),
            ("all effects, splines friction", splines, False),
            ("all effects, splines friction, locked", splines, True),
            ("circular spline grounded, splines friction",
             make_joint(grounded="circular_spline").set("friction.placement", "splines"), False),
            ("tanh hysteresis, splines friction",
             make_joint("tanh", "cubic").set("friction.placement", "splines"), False)]
    for e in EFFECTS:
        rows.append((f"only {e}", base.without(*(x for x in EFFECTS if x != e)), False))
        rows.append((f"all but {e}", base.without(e), False))
        rows.append((f"only {e}, mesh friction",
                     mesh.without(*(x for x in EFFECTS if x != e)), False))
    for hyst in ("maxwell", "tanh"):
        for comp in ("cubic", "two_segment", "three_segment", "linear"):
            rows.append((f"{hyst} hysteresis, {comp} spring", make_joint(hyst, comp), False))
    return rows


def test_every_effect_through_all_three_implementations():
    """docs/physics.md eqs. (1)-(12): the one-env kernel, the SIMD lanes and the numpy
    reference take the same substeps for every row of the effect table."""
    rows = _effect_table()
    ps = np.stack([L.pack(p) for _, p, _ in rows])
    flags = np.array([flags_of(p.effects, locked) for _, p, locked in rows], dtype=np.int64)
    locked = np.array([lk for _, _, lk in rows])
    xs = np.where(locked[:, None], L.initial_state(ps, flags, 0.3, 0.0),
                  L.initial_state(ps, flags, 0.3, None))
    n = len(rows)
    current = lambda k: 4.0 * np.sin(0.02 * k) + 1.0  # noqa: E731
    xk, xr = xs.copy(), xs.copy()
    bad = np.zeros(n, dtype=np.bool_)
    for k in range(300):
        u = np.full(n, current(k))
        kernel.step_serial(xk, ps, u, np.zeros(n), 1e-4, 10, flags, bad)
        xr = reference.step(xr, ps, u, np.zeros(n), 1e-4, 10, flags)
    xl, bad_l = _run_lanes(xs, ps, flags, current, 300)
    assert not bad.any() and not bad_l.any()
    scale = np.maximum(np.abs(xr), 1.0)
    for name, x in (("kernel", xk), ("lanes", xl)):
        err = np.max(np.abs(x - xr) / scale, axis=1)
        off = [rows[i][0] for i in np.flatnonzero(err > 1e-9)]
        assert not off, f"{name} differs from the reference for: {off} ({err.max():.3g})"
    # the table exercises what it names: the mesh rows move the friction off the output
    i = [r[0] for r in rows].index("all effects, mesh friction")
    j = [r[0] for r in rows].index("all effects")
    assert xk[i, L.TK] != xk[j, L.TK]
    # ... and the splines row reads another torque than the output row
    i = [r[0] for r in rows].index("all effects, splines friction")
    assert xk[i, L.TK] != xk[j, L.TK]


@pytest.mark.parametrize("grounded", ["flexspline", "circular_spline"])
def test_splines_placement_moves_like_output_and_reads_the_output_inertia(grounded):
    """docs/physics.md eq. (8): placement splines is the output placement's motion (the
    friction between the splines acts on the output at the output speed, one spline being
    grounded), with the state's torque the grounded spline's: J_o dw_o/dt + T_load, blind
    to the transmission friction (Tuttle §2.6 p. 91, §3 p. 113)."""
    out = make_joint(grounded=grounded).set("load.torque", 0.3)
    spl = out.set("friction.placement", "splines")
    ps = np.stack([L.pack(out), L.pack(spl)])
    fl = np.full(2, flags_of(out.effects), dtype=np.int64)
    xs = L.initial_state(ps, fl, 0.3, None)
    bad = np.zeros(2, dtype=np.bool_)
    dt, n_sub = 1e-4, 10
    j_o = out.load.inertia
    n_friction = 0
    for k in range(400):
        u = np.full(2, 4.0 * np.sin(0.02 * k) + 1.0)
        kernel.step_serial(xs, ps, u, np.zeros(2), dt, n_sub, fl, bad)
        moving = [L.TH_M, L.W_M, L.TH_O, L.W_O, L.CUR, L.DTH, L.E_DISS]
        assert np.array_equal(xs[0, moving], xs[1, moving])  # the same motion, to the bit
        # the spring torque (output placement) and the reading differ by the friction
        n_friction += abs(xs[0, L.TK] - xs[1, L.TK]) > 1e-3
    assert not bad.any()
    assert n_friction > 100  # the friction is there, and the splines reading leaves it out
    # one substep from the final state: the reading is the output's inertial torque plus load
    x1 = xs.copy()
    kernel.step_serial(x1, ps, np.full(2, 1.0), np.zeros(2), dt, 1, fl, bad)
    acc = (x1[1, L.W_O] - xs[1, L.W_O]) / dt
    assert x1[1, L.TK] == pytest.approx(j_o * acc + x1[1, L.T_LOAD], rel=1e-9, abs=1e-9)
