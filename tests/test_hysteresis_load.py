"""Load-history hysteresis and startup torque (Seyfferth figs 9-10, 15-16; docs/physics.md H1-H3):
the three implementations agree, and the load history does what the equations say."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import make_joint

from hdgym.effects import EFFECTS, flags_of
from hdgym.params import Hysteresis
from hdgym.physics import kernel, lanes, reference
from hdgym.physics import layout as L


def _loaded(p, width_slope=0.5, shape_slope=-2.0, startup_slope=2e-3, width=1.0, shape=2e3):
    h = Hysteresis(model="tanh", width=width, shape=shape, width_slope=width_slope,
                   shape_slope=shape_slope, startup_slope=startup_slope)
    return dataclasses.replace(p, hysteresis=h)


def _joints():
    base = [make_joint("tanh", "cubic"), make_joint("tanh", "linear", grounded="circular_spline")]
    out = []
    for p in base:
        q = _loaded(p)
        out += [q, q.without("hysteresis"), q.without("load_dependent_friction"),
                q.without("stribeck_friction", "stiction"), q.without(*EFFECTS),
                _loaded(p, shape_slope=-400.0)]  # gamma clamped at zero above 5 N m
    return out


def _batch(joints, locked):
    ps = np.stack([L.pack(p) for p in joints])
    flags = np.array([flags_of(p.effects, locked) for p in joints], dtype=np.int64)
    xs = L.initial_state(ps, flags, 0.3, 0.0 if locked else None)
    return xs, ps, flags


@pytest.mark.parametrize("locked", [False, True])
def test_three_implementations_agree(locked):
    xs, ps, flags = _batch(_joints(), locked)
    n = len(xs)
    cur = (lambda k: 2.0 * np.sin(0.05 * k)) if locked else (lambda k: 4.0 * np.sin(0.02 * k) + 1)
    xk, xr, xl = xs.copy(), xs.copy(), xs.copy()
    lb = lanes.LaneBatch(xl, ps, flags, 1e-4)
    bad = np.zeros(n, dtype=np.bool_)
    for k in range(300):
        u = np.full(n, cur(k))
        z = np.zeros(n)
        kernel.step_serial(xk, ps, u, z, 1e-4, 10, flags, bad)
        xr = reference.step(xr, ps, u, z, 1e-4, 10, flags)
        lb.step(u, z, 10, xl, bad)
    scale = np.maximum(np.abs(xr), 1.0)
    assert np.all(np.isfinite(xk))
    np.testing.assert_allclose(xk / scale, xr / scale, rtol=0, atol=1e-9)
    np.testing.assert_allclose(xl / scale, xr / scale, rtol=0, atol=1e-9)
    # the load history ran (tanh joints): it is the largest |T| since the last reversal
    assert np.all(xk[:-1:6, L.HZ + 4] > 0)


def _locked_run(p, currents, n_sub=10, dt=1e-4):
    row = L.pack(p)[None, :]
    flags = np.array([flags_of(p.effects, True)], dtype=np.int64)
    x = L.initial_state(row, flags, 0.0, 0.0)
    out = np.empty((len(currents), L.N_STATE))
    bad = np.zeros(1, dtype=np.bool_)
    for k, i in enumerate(currents):
        kernel.step_serial(x, row, np.array([i]), np.zeros(1), dt, n_sub, flags, bad)
        out[k] = x[0]
    return out


def test_loop_width_grows_with_the_reversal_load():
    """Slow locked-output sine: the torque gap between loading and unloading branches at the
    loop's centre is 2 B_f = 2 (width + width_slope L) with L the load at the reversals."""
    p0 = make_joint("tanh", "linear").without("kinematic_error", "coulomb_friction",
                                             "stribeck_friction", "stiction",
                                             "position_dependent_friction")
    # damp the 54 Hz locked mode: its ripples would be reversals and reset the history
    p0 = p0.set("friction.input.viscous", 0.05).set("friction.input.cubic", 0.0)
    t = np.arange(4000) * 1e-3
    gaps = {}
    for slope in (0.0, 0.3):
        p = _loaded(p0, width_slope=slope, shape_slope=0.0, startup_slope=0.0, shape=2e4)
        st = _locked_run(p, 3.0 * np.sin(2 * np.pi * 1.0 * t))
        last = t >= 3.0
        x = st[last, L.DTH]
        tk = st[last, L.TK]
        up = np.gradient(x) > 0
        at0 = []
        for branch in (up, ~up):
            o = np.argsort(x[branch])
            at0.append(np.interp(0.0, x[branch][o], tk[branch][o]))
        gaps[slope] = (at0[0] - at0[1], np.max(np.abs(tk)))  # loading above unloading
    gap0, _ = gaps[0.0]
    gap1, peak = gaps[0.3]
    assert gap0 == pytest.approx(2.0, rel=0.01)
    assert gap1 == pytest.approx(2.0 * (1.0 + 0.3 * peak), rel=0.01)


def test_startup_torque_grows_with_load_history():
    """Locked output: load the spring, then hold a current whose net torque on the WG sits
    between B_m0 and B_m0 + startup_slope L. With the startup growth the WG stays stuck;
    with load_dependent_friction off it slips back."""
    p0 = make_joint("tanh", "linear").without("kinematic_error", "position_dependent_friction",
                                             "stribeck_friction", "stiction")
    p = _loaded(p0, width_slope=0.0, shape_slope=0.0, startup_slope=2e-3)
    kt, r = p.motor.torque_constant, p.ratio
    load = 40.0  # N m at the flexspline
    i_load = load / (kt * r) + p.friction.input.coulomb / kt
    hold = 2.0  # s of ramp then hold
    n = int(hold / 1e-3)
    ramp = np.linspace(0.0, i_load, n)
    moved = {}
    for q in (p, p.without("load_dependent_friction")):
        st = _locked_run(q, ramp)
        tk = st[-1, L.TK]
        # a current whose net WG torque is 1.5 B_m0 below the spring's pull: inside
        # B_m0 + startup_slope*L (= 0.05 + 0.08) but beyond B_m0 alone
        i_hold = (tk / r - 1.5 * p.friction.input.coulomb) / kt
        st2 = _locked_run_from(q, st[-1], np.full(500, i_hold))
        moved[q.effects.count("load_dependent_friction")] = abs(st2[-1, L.TH_M] - st[-1, L.TH_M])
    assert moved[1] < 1e-5  # stuck (settling of the current loop only): the startup torque grew
    assert moved[0] > 1e-2  # slips back without the growth


def _locked_run_from(p, x0, currents):
    row = L.pack(p)[None, :]
    flags = np.array([flags_of(p.effects, True)], dtype=np.int64)
    x = x0[None, :].copy()
    out = np.empty((len(currents), L.N_STATE))
    bad = np.zeros(1, dtype=np.bool_)
    for k, i in enumerate(currents):
        kernel.step_serial(x, row, np.array([i]), np.zeros(1), 1e-4, 10, flags, bad)
        out[k] = x[0]
    return out


def test_slopes_need_the_tanh_model_and_signs_are_checked():
    with pytest.raises(ValueError, match="hysteresis.width_slope"):
        Hysteresis(model="maxwell", width_slope=0.1)
    with pytest.raises(ValueError, match="hysteresis.startup_slope"):
        Hysteresis(model="tanh", startup_slope=-1e-3)
    with pytest.raises(ValueError, match="hysteresis.width_slope"):
        Hysteresis(model="tanh", width_slope=-0.1)
    assert Hysteresis(model="tanh", shape_slope=-3.0).shape_slope == -3.0


def test_virgin_curve_is_the_masing_curve():
    """From rest (no reversal yet) the element loads along B_f tanh(2 gamma phi), in either
    direction (docs/physics.md eq. H1): its initial slope 2 gamma B_f is the slope just after
    a reversal from a saturated branch, as Masing's rule asks."""
    p0 = make_joint("tanh", "linear").without("kinematic_error", "coulomb_friction",
                                             "stribeck_friction", "stiction",
                                             "position_dependent_friction")
    p0 = p0.set("friction.input.viscous", 0.05).set("friction.input.cubic", 0.0)
    p = _loaded(p0, width_slope=0.0, shape_slope=0.0, startup_slope=0.0, shape=2e4)
    k1, bf, gam = p.compliance.stiffness, p.hysteresis.width, p.hysteresis.shape
    ramp = np.linspace(0.0, 3.0, 3000)
    for sign in (1.0, -1.0):
        st = _locked_run(p, sign * ramp)
        phi, tk = st[:, L.DTH], st[:, L.TK]
        t_h = tk - k1 * phi
        small = np.abs(phi) < 2.0 / gam  # the steep part of the virgin curve
        assert small.sum() > 20
        np.testing.assert_allclose(t_h[small], bf * np.tanh(2.0 * gam * phi[small]),
                                   atol=0.02 * bf)
    # after the first reversal from near saturation: the Seyfferth branch (slope gamma (B_f +
    # |dT*|), i.e. about 2 gamma B_f), unchanged by the virgin rule
    st = _locked_run(p, np.concatenate([ramp, ramp[::-1]]))
    phi, tk = st[:, L.DTH], st[:, L.TK]
    rev = int(np.argmax(phi))
    after = slice(rev + 5, rev + 40)
    slope = np.polyfit(phi[after], (tk - k1 * phi)[after], 1)[0]
    t_star = (tk - k1 * phi)[rev]
    assert slope == pytest.approx(gam * (bf + t_star), rel=0.1)
    assert st[-1, L.HZ + 5] == 0.0 and st[rev - 10, L.HZ + 5] == 1.0
