"""Plain-numpy reference of the joint step, vectorized over the batch: docs/physics.md
eqs. (1)-(13).

Slow, readable and independent of numba: tests check that the compiled
:mod:`hdgym.physics.kernel` agrees with it. Same algorithm (see the kernel's
docstring), written with whole-batch array operations and ``np.where``
instead of per-env branches.
"""

from __future__ import annotations

import numpy as np

from hdgym.effects import BIT, LOCKED_OUTPUT_BIT
from hdgym.params import MAX_HARMONICS, MAX_RIPPLES, MAX_SLIP_ELEMENTS
from hdgym.physics import layout as L
from hdgym.physics.kernel import REVERSAL_DEADBAND


def _on(flags: np.ndarray, name: str) -> np.ndarray:
    return (flags & BIT[name]) != 0


def spring(x: np.ndarray, p: np.ndarray, flags: np.ndarray) -> np.ndarray:
    """Spring torque for a batch of torsions ``x`` (output rad), N m: eq. (3)."""
    k1 = p[:, L.K1]
    lin = k1 * x
    ax = np.abs(x)
    s = np.sign(x)
    cubic = lin + p[:, L.K3] * x**3
    two = lin + p[:, L.K0] * np.maximum(ax - p[:, L.KNEE], 0.0) * s
    th1 = p[:, L.ST1] / k1
    with np.errstate(divide="ignore", invalid="ignore"):
        th2 = th1 + (p[:, L.ST2] - p[:, L.ST1]) / p[:, L.SK2]
    three = np.where(ax <= th1, lin,
                     np.where(ax <= th2, s * (p[:, L.ST1] + p[:, L.SK2] * (ax - th1)),
                              s * (p[:, L.ST2] + p[:, L.SK3] * (ax - th2))))
    model = p[:, L.CMODEL]
    nonlin = np.select([model == 1, model == 2, model == 3], [cubic, two, three], lin)
    return np.where(_on(flags, "nonlinear_stiffness"), nonlin, lin)


def spring_energy(x: np.ndarray, p: np.ndarray, flags: np.ndarray) -> np.ndarray:
    """Potential energy stored in the spring at torsion ``x``, J."""
    k1 = p[:, L.K1]
    ax = np.abs(x)
    lin = 0.5 * k1 * x**2
    cubic = lin + 0.25 * p[:, L.K3] * x**4
    two = lin + 0.5 * p[:, L.K0] * np.maximum(ax - p[:, L.KNEE], 0.0) ** 2
    th1 = p[:, L.ST1] / k1
    with np.errstate(divide="ignore", invalid="ignore"):
        th2 = th1 + (p[:, L.ST2] - p[:, L.ST1]) / p[:, L.SK2]
    e1 = 0.5 * k1 * th1**2
    e2 = e1 + p[:, L.ST1] * (th2 - th1) + 0.5 * p[:, L.SK2] * (th2 - th1) ** 2
    d1 = ax - th1
    d2 = ax - th2
    three = np.where(ax <= th1, lin, np.where(
        ax <= th2, e1 + p[:, L.ST1] * d1 + 0.5 * p[:, L.SK2] * d1**2,
        e2 + p[:, L.ST2] * d2 + 0.5 * p[:, L.SK3] * d2**2))
    model = p[:, L.CMODEL]
    nonlin = np.select([model == 1, model == 2, model == 3], [cubic, two, three], lin)
    return np.where(_on(flags, "nonlinear_stiffness"), nonlin, lin)


def _ke(th_m: np.ndarray, p: np.ndarray, flags: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Kinematic error and its slope: eq. (1)."""
    ke = np.zeros_like(th_m)
    dke = np.zeros_like(th_m)
    on = _on(flags, "kinematic_error")
    for k in range(MAX_HARMONICS):
        use = on & (k < p[:, L.NKE])
        a = p[:, L.KE_ORD + k] * th_m + p[:, L.KE_PH + k]
        amp = np.where(use, p[:, L.KE_AMP + k], 0.0)
        ke += amp * np.sin(a)
        dke += amp * p[:, L.KE_ORD + k] * np.cos(a)
    return ke, dke


def _level(p: np.ndarray, base: int, w: np.ndarray, th_in: np.ndarray, th_out: np.ndarray,
           extra: np.ndarray, flags: np.ndarray) -> np.ndarray:
    """Coulomb-type friction level of one side: eq. (7)."""
    fc = p[:, base + L.F_FC]
    fs = p[:, base + L.F_FS]
    r = w / p[:, base + L.F_WS]
    stuck_level = np.where(_on(flags, "stiction") | _on(flags, "stribeck_friction"), fs, fc)
    running = np.where(_on(flags, "stribeck_friction"), fc + (fs - fc) * np.exp(-r * r), fc)
    level = np.where(_on(flags, "coulomb_friction"), np.where(w == 0.0, stuck_level, running), 0.0)
    for k in range(MAX_RIPPLES):
        use = _on(flags, "position_dependent_friction") & (k < p[:, base + L.F_NRIP])
        ang = np.where(p[:, base + L.F_RFRAME + k] == 0.0, th_in, th_out)
        level = level + np.where(use, p[:, base + L.F_RAMP + k] * np.sin(
            p[:, base + L.F_RORD + k] * ang + p[:, base + L.F_RPH + k]), 0.0)
    return np.maximum(level + extra, 0.0)


def _visc(p: np.ndarray, base: int, w: np.ndarray, flags: np.ndarray) -> np.ndarray:
    """Secant viscous coefficient of one side: eq. (7)."""
    b1 = p[:, base + L.F_B1]
    b2 = p[:, base + L.F_B2]
    w2 = w * w
    with np.errstate(divide="ignore", invalid="ignore"):
        wpk2 = np.where(b2 < 0, b1 / (-3.0 * np.where(b2 < 0, b2, -1.0)), np.inf)
        wpk = np.sqrt(wpk2)
        clamped = (b1 * wpk + b2 * wpk2 * wpk) / np.abs(w)
    coeff = np.where(w2 <= wpk2, b1 + b2 * w2, clamped)
    return np.where(_on(flags, "viscous_friction"), coeff, 0.0)


def _advance(w: np.ndarray, tau: np.ndarray, inertia: np.ndarray, visc: np.ndarray,
             level: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """New speeds and dissipated power: eq. (11)."""
    denom = 1.0 + dt * visc / inertia
    v_free = (w + dt * tau / inertia) / denom
    dv = dt * level / inertia / denom
    stuck = np.abs(v_free) <= dv
    v = np.where(stuck, 0.0, v_free - np.sign(v_free) * dv)
    return v, visc * v * v + level * np.abs(v)


def substep(xs: np.ndarray, ps: np.ndarray, i_cmd: np.ndarray, t_ext: np.ndarray, dt: float,
            flags: np.ndarray) -> np.ndarray:
    """One substep for a batch; returns the new state array (input untouched)."""
    x = xs.copy()
    p = ps
    flags = np.asarray(flags, dtype=np.int64)
    r = p[:, L.RATIO]
    th_m, w_m, th_o, w_o = x[:, L.TH_M], x[:, L.W_M], x[:, L.TH_O], x[:, L.W_O]
    ke, dke = _ke(th_m, p, flags)
    # eq. (2)
    dth = th_m / r - th_o - ke
    gear = 1.0 / r - dke
    ddth = w_m * gear - w_o
    d_inc = dth - x[:, L.DTH]
    x[:, L.DTH] = dth
    hyst = _on(flags, "hysteresis")
    tanh_memory = p[:, L.HMODEL] == 1.0  # kept with hysteresis off: the load history
    tanh_model = hyst & tanh_memory
    # Maxwell-slip: eq. (4)
    t_h = np.zeros(len(x))
    diss = np.zeros(len(x))
    for k in range(MAX_SLIP_ELEMENTS):
        use = hyst & ~tanh_model & (k < p[:, L.NSLIP])
        kap = p[:, L.SLIP_K + k]
        wk = p[:, L.SLIP_W + k]
        f = x[:, L.HZ + k] + kap * d_inc
        fc = np.clip(f, -wk, wk)
        with np.errstate(divide="ignore", invalid="ignore"):
            slip = np.where(kap > 0, wk * np.abs(f - fc) / kap, 0.0)
        x[:, L.HZ + k] = np.where(use, fc, x[:, L.HZ + k])
        t_h += np.where(use, fc, 0.0)
        diss += np.where(use, slip, 0.0)
    # tanh element, last-reversal memory, load history: eq. (5), docs/physics.md eqs. H1-H3
    s = x[:, L.HZ + 2]
    s_new = np.where(d_inc > REVERSAL_DEADBAND, 1.0, np.where(d_inc < -REVERSAL_DEADBAND, -1.0, s))
    rev = tanh_memory & (s_new != s)
    a_k = np.abs(x[:, L.TK])  # transmitted torque of the previous substep
    load = np.where(rev, a_k, np.maximum(x[:, L.HZ + 4], a_k))
    x[:, L.HZ + 4] = np.where(tanh_memory, load, x[:, L.HZ + 4])
    x[:, L.HZ] = np.where(rev, dth - d_inc, x[:, L.HZ])
    x[:, L.HZ + 1] = np.where(rev, x[:, L.HZ + 3], x[:, L.HZ + 1])
    # virgin until the first reversal: the first move (from no direction, s = 0) stays virgin
    x[:, L.HZ + 5] = np.where(rev, np.where(s == 0.0, 1.0, 0.0), x[:, L.HZ + 5])
    x[:, L.HZ + 2] = np.where(rev, s_new, s)
    s = x[:, L.HZ + 2]
    dts = x[:, L.HZ + 1]
    width = p[:, L.TANH_B] + p[:, L.TANH_B1] * load
    # eq. H1: the virgin curve has twice the shape factor (Masing's rule)
    gam = (1.0 + x[:, L.HZ + 5]) * np.maximum(p[:, L.TANH_G] + p[:, L.TANH_G1] * load, 0.0)
    th_tanh = dts + (s * width - dts) * np.tanh(gam * s * (dth - x[:, L.HZ]))
    x[:, L.HZ + 3] = np.where(tanh_model, th_tanh, x[:, L.HZ + 3])
    t_h = np.where(tanh_model, th_tanh, t_h)
    # eqs. (3), (6)
    t_k = spring(dth, p, flags) + p[:, L.CDAMP] * ddth + t_h
    x[:, L.TK] = t_k
    # amplifier: eq. (9); current loop: eq. (10)
    amp = _on(flags, "amplifier_saturation")
    hi = (p[:, L.V_MAX] - p[:, L.KB] * w_m) / p[:, L.RES]
    lo = (-p[:, L.V_MAX] - p[:, L.KB] * w_m) / p[:, L.RES]
    limited = np.minimum(np.maximum(np.clip(i_cmd, -p[:, L.I_MAX], p[:, L.I_MAX]), lo), hi)
    i_t = np.where(amp, limited, i_cmd)
    alpha = 1.0 - np.exp(-2.0 * np.pi * p[:, L.BW] * dt)
    cur = x[:, L.CUR] + alpha * (i_t - x[:, L.CUR])
    x[:, L.CUR] = cur
    t_m = p[:, L.KT] * cur
    x[:, L.T_MOTOR] = t_m
    startup = np.where(tanh_memory & _on(flags, "load_dependent_friction"),  # eq. H4
                       p[:, L.STARTUP1] * x[:, L.HZ + 4], 0.0)
    mu = np.where(_on(flags, "load_dependent_friction"), p[:, L.MU_LOAD], 0.0)
    # eq. (8): the transmission friction acts at the output speed (placements output and
    # splines) or at the mesh speed w_m * gear, reflected to the WG by `gear` (placement mesh)
    mesh = p[:, L.MESH] == 1.0
    v_rel = np.where(mesh, w_m * gear, w_o)
    lvl_t = _level(p, L.FOUT, v_rel, th_m, th_o, mu * np.abs(t_k), flags)
    vis_t = _visc(p, L.FOUT, v_rel, flags)
    g_m = np.where(mesh, gear, 0.0)
    lvl = _level(p, L.FIN, w_m, th_m, th_o, startup, flags) + g_m * lvl_t
    vis = _visc(p, L.FIN, w_m, flags) + g_m * g_m * vis_t
    w_m_new, pm = _advance(w_m, t_m - t_k * gear, p[:, L.J_M], vis, lvl, dt)
    t_load = p[:, L.LOAD_T] + p[:, L.GRAV] * np.sin(th_o) + t_ext
    w_o_free, po = _advance(w_o, t_k - t_load, p[:, L.J_O], np.where(mesh, 0.0, vis_t),
                            np.where(mesh, 0.0, lvl_t), dt)
    locked = (flags & LOCKED_OUTPUT_BIT) != 0
    w_o_new = np.where(locked, 0.0, w_o_free)
    po = np.where(locked, 0.0, po)
    x[:, L.T_LOAD] = t_load
    # placement splines: the state's torque is the grounded spline's, J_o dw_o/dt + T_load
    sense = (p[:, L.MESH] == 2.0) & ~locked
    x[:, L.TK] = np.where(sense, p[:, L.J_O] * (w_o_new - w_o) / dt + t_load, t_k)
    x[:, L.W_M] = w_m_new
    x[:, L.W_O] = w_o_new
    # eq. (12)
    x[:, L.TH_M] = th_m + dt * w_m_new
    x[:, L.TH_O] = th_o + dt * w_o_new
    # eq. (13)
    x[:, L.E_DISS] += dt * (pm + po + p[:, L.CDAMP] * ddth**2) + diss
    x[:, L.W_MOTOR] += dt * t_m * w_m_new
    x[:, L.W_LOAD] -= dt * t_load * w_o_new
    return x


def step(xs: np.ndarray, ps: np.ndarray, i_cmd: np.ndarray, t_ext: np.ndarray, dt: float,
         n_sub: int, flags: np.ndarray) -> np.ndarray:
    """``n_sub`` substeps of ``dt`` s for a batch (the reference of ``kernel.step_*``)."""
    for _ in range(n_sub):
        xs = substep(xs, ps, i_cmd, t_ext, dt, flags)
    return xs


def mechanical_energy(xs: np.ndarray, ps: np.ndarray, flags: np.ndarray) -> np.ndarray:
    """Kinetic + spring + elastic hysteresis energy of a batch, J.

    Uses the stored torsion ``DTH`` (consistent with the hysteresis memory).
    The tanh hysteresis element has no stored-energy function and is left out.
    """
    flags = np.asarray(flags, dtype=np.int64)
    kin = 0.5 * ps[:, L.J_M] * xs[:, L.W_M] ** 2 + 0.5 * ps[:, L.J_O] * xs[:, L.W_O] ** 2
    ke, _ = _ke(xs[:, L.TH_M], ps, flags)
    dth = xs[:, L.TH_M] / ps[:, L.RATIO] - xs[:, L.TH_O] - ke
    pot = spring_energy(dth, ps, flags)
    maxwell = _on(flags, "hysteresis") & (ps[:, L.HMODEL] == 0.0)
    for k in range(MAX_SLIP_ELEMENTS):
        kap = ps[:, L.SLIP_K + k]
        with np.errstate(divide="ignore", invalid="ignore"):
            e = np.where(kap > 0, xs[:, L.HZ + k] ** 2 / (2 * kap), 0.0)
        pot += np.where(maxwell & (k < ps[:, L.NSLIP]), e, 0.0)
    return kin + pot
