"""Linear two-inertia model of a joint and PID design with python-control.

:func:`linearize` gives a ``control.StateSpace`` at an operating point:

    states  theta_m (rad), omega_m (rad/s), theta_o (rad), omega_o (rad/s), i (A)
    input   current command (A)
    outputs motor_velocity (rad/s), output_angle (rad), output_torque (N m),
            motor_angle (rad), output_velocity (rad/s)

    J_m omega_m' = K_t i - g T_k - b_m omega_m
    J_o omega_o' = T_k - b_o omega_o
    T_k          = k (g theta_m - theta_o) + c (g omega_m - omega_o)
    i'           = 2 pi f_i (i_cmd - i)                  (amplifier current loop)

with ``g = 1/ratio - theta_ke'(theta_m0)`` (the gear factor through the
kinematic error at the operating WG angle), ``k`` the compliance slope at the
operating torsion (plus the stuck Maxwell-slip stiffness when hysteresis is
on: small reversals do not slip the elements), ``b`` the viscous
coefficients; ``g`` and ``k`` come from :mod:`hdgym.linearize`. Coulomb-type
friction, stiction and amplifier saturation are not linear and are left out.

:func:`design_pid` places a PID's gain crossover at a chosen frequency with
a chosen phase margin and checks the result with :func:`loop_margins`
(python-control's margins on the frequency response).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import control
import numpy as np
from scipy.optimize import brentq

from controllers.base import check_nonneg, check_positive
from controllers.pid import PID
from hdgym.linearize import gear_factor, stiffness, viscous
from hdgym.params import JointParams

OUTPUTS = ("motor_velocity", "output_angle", "output_torque", "motor_angle", "output_velocity")
STATES = ("motor_angle", "motor_velocity", "output_angle", "output_velocity", "motor_current")


def linearize(p: JointParams, *, torque: float = 0.0, motor_angle: float = 0.0,
              hysteresis: bool = True, current_loop: bool = True) -> control.StateSpace:
    """The joint as a two-inertia ``control.ss`` at an operating point.

    Args:
        p: the joint (its ``effects`` decide which terms appear).
        torque: operating flexspline torque, N m (sets the compliance slope).
        motor_angle: operating WG angle, rad (sets the kinematic-error slope).
        hysteresis: add the stuck Maxwell-slip stiffness (small signals).
        current_loop: model the amplifier's first-order current loop
            (otherwise the current follows the command at once).
    """
    g = gear_factor(p, motor_angle)
    k = stiffness(p, torque, hysteresis)
    c = p.compliance.damping
    bm, bo = viscous(p, motor_angle)
    jm, jo, kt = p.motor.inertia, p.load.inertia, p.motor.torque_constant
    wi = 2 * math.pi * p.amplifier.bandwidth
    # T_k = k g th_m - k th_o + c g w_m - c w_o
    a = np.zeros((5, 5))
    a[0, 1] = 1.0
    a[1] = [-g * k * g / jm, -(bm + g * c * g) / jm, g * k / jm, g * c / jm, kt / jm]
    a[2, 3] = 1.0
    a[3] = [k * g / jo, c * g / jo, -k / jo, -(bo + c) / jo, 0.0]
    b = np.zeros((5, 1))
    if current_loop:
        a[4, 4] = -wi
        b[4, 0] = wi
    else:  # i follows the command: fold it into the input
        b[1, 0] = kt / jm
        a[1, 4] = 0.0
    cm = np.zeros((5, 5))
    cm[0, 1] = 1.0
    cm[1, 2] = 1.0
    cm[2] = [k * g, c * g, -k, -c, 0.0]
    cm[3, 0] = 1.0
    cm[4, 3] = 1.0
    return control.ss(a, b, cm, np.zeros((5, 1)), inputs=["current_command"],
                      outputs=list(OUTPUTS), states=list(STATES), name="joint")


def output(sys: control.StateSpace, name: str) -> control.StateSpace:
    """The SISO channel from the current command to output ``name``."""
    if name not in OUTPUTS:
        raise ValueError(f"output must be one of {OUTPUTS}, got {name!r}")
    j = OUTPUTS.index(name)
    return control.ss(sys.A, sys.B, sys.C[j:j + 1], sys.D[j:j + 1])


def resonance_hz(p: JointParams, torque: float = 0.0) -> float:
    """Torsional natural frequency of the two-inertia joint (free output), Hz."""
    k = stiffness(p, torque)
    jm_out = p.motor.inertia * p.ratio ** 2
    jo = p.load.inertia
    return math.sqrt(k * (jm_out + jo) / (jm_out * jo)) / (2 * math.pi)


@dataclass(frozen=True)
class PIDDesign:
    """A PID designed on a linear model: gains and the margins :func:`loop_margins` reports.

    ``C(s) = kp + ki/s + kd s/(tf s + 1)`` (units: A per rad of the fed-back angle).
    """

    kp: float
    ki: float
    kd: float
    tf: float
    crossover_hz: float
    phase_margin_deg: float
    gain_margin_db: float
    loop: control.TransferFunction
    loop_filter: control.TransferFunction | None = None

    def controller_tf(self) -> control.TransferFunction:
        """``C(s)`` including the loop filter when there is one."""
        s = control.tf("s")
        c = self.kp + self.ki / s + self.kd * s / (self.tf * s + 1)
        return c if self.loop_filter is None else c * self.loop_filter

    def pid(self, dt: float, u_limit: float = math.inf, **kwargs: object) -> PID:
        """A discrete :class:`PID` with these gains and limits ``+-u_limit``."""
        return PID(self.kp, self.ki, self.kd, dt=dt, tf=self.tf, u_min=-u_limit,
                   u_max=u_limit, **kwargs)


def loop_margins(loop: control.LTI, around: float) -> tuple[float, float, float, float]:
    """(gain margin, phase margin in deg, phase and gain crossover in rad/s) of ``loop``.

    The crossings of ``|L| = 1`` and of the negative real axis are bracketed
    on the frequency response over four decades either side of ``around``
    (rad/s) and refined by root finding on ``L(jw)`` itself; the margins are
    then picked as :func:`control.margin` picks them (the gain margin closest
    to 0 dB, the smallest phase margin). :func:`control.margin`'s polynomial
    method overflows on a high-order loop (a PID, a notch, a Padé delay and
    a resonance) and its frequency-response method takes a minute on a grid
    this fine.
    """
    def at(lw: float) -> complex:
        return complex(np.asarray(loop(1j * math.exp(lw))).reshape(-1)[0])

    lws = np.linspace(math.log(around) - 4 * math.log(10), math.log(around) + 4 * math.log(10),
                      8001)
    h = np.asarray(loop(1j * np.exp(lws))).reshape(-1)
    with np.errstate(divide="ignore"):
        g = np.log(np.abs(h))
    wc = [math.exp(brentq(lambda lw: math.log(abs(at(lw))), lws[i], lws[i + 1]))
          for i in np.nonzero((g[:-1] < 0) != (g[1:] < 0))[0]]
    cross = np.nonzero(((h.imag[:-1] < 0) != (h.imag[1:] < 0))
                       & (h.real[:-1] + h.real[1:] < 0))[0]
    w180 = [math.exp(brentq(lambda lw: at(lw).imag, lws[i], lws[i + 1])) for i in cross]
    gms = [1.0 / abs(at(math.log(w))) for w in w180]
    pms = [float(np.remainder(np.degrees(np.angle(at(math.log(w)))), 360.0) - 180.0)
           for w in wc]
    k = int(np.argmin(np.abs(np.log(gms)))) if gms else -1
    m = int(np.argmin(np.abs(pms))) if pms else -1
    return (gms[k] if k >= 0 else math.inf, pms[m] if m >= 0 else math.inf,
            w180[k] if k >= 0 else math.nan, wc[m] if m >= 0 else math.nan)


def design_pid(plant: control.LTI, crossover_hz: float, phase_margin_deg: float = 50.0, *,
               ti_over_td: float = 4.0, derivative_filter: float = 8.0,
               delay: float = 0.0, loop_filter: control.LTI | None = None) -> PIDDesign:
    """PID with gain crossover at ``crossover_hz`` and the given phase margin.

    The structure is ``kp (1 + 1/(Ti s) + Td s/(Td/N s + 1))`` with ``Ti =
    ti_over_td * Td`` and ``N = derivative_filter``; ``Td`` is found so that
    the loop phase at the crossover is ``-180 deg + phase_margin``, then
    ``kp`` so that the loop gain there is one. The sample-and-hold and
    computation delay (``delay``, s, e.g. ``1.5 * dt``) enters as a Padé
    approximation. The achieved margins come from :func:`loop_margins`.

    Args:
        plant: SISO system from current (A) to the fed-back angle (rad).
        loop_filter: a filter in series with the PID (e.g. a
            :func:`controllers.filters.notch` at the resonance); designed for.
        crossover_hz: wanted gain crossover, Hz (> 0).
        phase_margin_deg: wanted phase margin, deg (0 < PM < 90).

    Raises:
        ValueError: naming the setting when the phase margin cannot be reached
            at that crossover with this PID structure.
    """
    wc = 2 * math.pi * check_positive("crossover_hz", crossover_hz, "Hz")
    pm = float(phase_margin_deg)
    if not 0 < pm < 90:
        raise ValueError(f"phase_margin_deg must be in (0, 90) deg, got {phase_margin_deg!r}")
    alpha = check_positive("ti_over_td", ti_over_td)
    nf = check_positive("derivative_filter", derivative_filter)
    delay = check_nonneg("delay", delay, "s")
    if delay > 0:
        num, den = control.pade(delay, 3)
        plant = plant * control.tf(num, den)
    if loop_filter is not None:
        loop_filter = control.tf(loop_filter)
        plant = plant * loop_filter
    pj = complex(np.asarray(plant(1j * wc)).reshape(-1)[0])
    target = -math.pi + math.radians(pm) - np.angle(pj)
    target = (target + math.pi) % (2 * math.pi) - math.pi

    def shape(td: float) -> complex:
        s = 1j * wc
        return 1 + 1 / (alpha * td * s) + td * s / (td / nf * s + 1)

    tds = np.logspace(-4, 3, 3000) / wc
    err = np.array([np.angle(shape(td)) - target for td in tds])
    roots = np.nonzero(np.sign(err[:-1]) != np.sign(err[1:]))[0]
    if roots.size == 0:
        best = math.degrees(max(np.angle(shape(td)) for td in tds))
        raise ValueError(f"phase_margin_deg: {pm:g} deg is not reachable at crossover_hz "
                         f"{crossover_hz:g} Hz (needs {math.degrees(target):.1f} deg of PID "
                         f"phase, at most {best:.1f} available)")
    i = roots[-1]
    lo, hi = tds[i], tds[i + 1]
    for _ in range(60):
        mid = math.sqrt(lo * hi)
        if np.sign(np.angle(shape(mid)) - target) == np.sign(err[i]):
            lo = mid
        else:
            hi = mid
    td = math.sqrt(lo * hi)
    kp = 1.0 / abs(shape(td) * pj)
    ki = kp / (alpha * td)
    kd = kp * td
    tf = td / nf
    s = control.tf("s")
    cs = kp + ki / s + kd * s / (tf * s + 1)
    loop = control.minreal(cs * control.tf(plant), verbose=False)
    gm, pm_got, _, wcp = loop_margins(loop, wc)
    gm_db = 20 * math.log10(gm) if gm and np.isfinite(gm) and gm > 0 else math.inf
    return PIDDesign(kp=float(kp), ki=float(ki), kd=float(kd), tf=float(tf),
                     crossover_hz=float(wcp / (2 * math.pi)) if np.isfinite(wcp) else math.nan,
                     phase_margin_deg=float(pm_got), gain_margin_db=float(gm_db), loop=loop,
                     loop_filter=loop_filter)


def closed_loop(p: JointParams, design: PIDDesign, feedback: str = "motor", *,
                delay: float = 0.0, torque: float = 0.0) -> control.TransferFunction:
    """Output angle per (output-referred) reference of a position PID on the linear joint.

    With ``feedback="motor"`` the PID sees ``ratio * reference - theta_m``; the
    result is the ``T(s)`` of the repetitive-control stability condition.
    """
    sys = linearize(p, torque=torque)
    pm = control.tf(output(sys, "motor_angle"))
    po = control.tf(output(sys, "output_angle"))
    c = design.controller_tf()
    if delay > 0:
        num, den = control.pade(delay, 3)
        c = c * control.tf(num, den)
    if feedback == "motor":
        return control.minreal(p.ratio * c * po / (1 + c * pm), verbose=False)
    if feedback == "output":
        return control.minreal(c * po / (1 + c * po), verbose=False)
    raise ValueError(f"feedback must be 'motor' or 'output', got {feedback!r}")


#: effects switched off for small-signal frequency-response checks (Coulomb-type
#: friction, slip hysteresis, angle-dependent kinematic error, amplifier clipping)
NONLINEAR_EFFECTS = ("coulomb_friction", "stribeck_friction", "stiction",
                     "position_dependent_friction", "load_dependent_friction", "hysteresis",
                     "kinematic_error", "amplifier_saturation")


def small_signal_joint(p: JointParams) -> JointParams:
    """``p`` with the non-linear effects of :data:`NONLINEAR_EFFECTS` switched off."""
    return p.without(*[e for e in NONLINEAR_EFFECTS if e in p.effects])


def simulated_response(p: JointParams, channel: str = "motor_velocity", *,
                       duration: float = 60.0, amplitude: float | None = None,
                       cutoff_hz: float = 200.0, seed: int = 0,
                       segment: float = 2.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """H1 estimate of the simulated response from current command to ``channel``.

    Band-limited random current (the ``random:AMPS:CUTOFF`` command) drives
    :class:`hdgym.sim.Simulator` on the true states; the H1 estimate is
    ``S_uy / S_uu`` (Welch, Hann windows of ``segment`` s, 50 % overlap).

    Args:
        p: the joint (use :func:`small_signal_joint` for a linear comparison).
        channel: ``motor_velocity``, ``output_angle``, ``output_torque``,
            ``motor_angle`` or ``output_velocity``.
        amplitude: current amplitude, A (default 10 % of the amplifier limit).

    Returns:
        (frequencies Hz, complex H1 in channel units per A, coherence).
    """
    from scipy import signal

    from hdgym.sim import Simulator

    if channel not in OUTPUTS:
        raise ValueError(f"channel must be one of {OUTPUTS}, got {channel!r}")
    amp = 0.1 * p.amplifier.current_limit if amplitude is None else amplitude
    sim = Simulator(p, sensors=False)
    rec = sim.run(f"random:{amp}:{cutoff_hz}", duration, seed=seed)
    u = np.asarray(rec.columns["current_command"])
    y = np.asarray(rec.columns[channel])
    fs = 1.0 / sim.ctrl_dt
    n = int(segment * fs)
    # row k holds y(t_k) and the command applied from t_k on: y responds to u[:-1]
    u, y = u[:-1], y[1:]
    if channel.endswith("angle"):
        y = signal.detrend(y)
    f, puy = signal.csd(u, y, fs=fs, nperseg=n)
    _, puu = signal.welch(u, fs=fs, nperseg=n)
    _, coh = signal.coherence(u, y, fs=fs, nperseg=n)
    return f, puy / puu, coh


def model_response(sys: control.StateSpace, channel: str, freqs_hz: np.ndarray,
                   dt: float | None = None) -> np.ndarray:
    """Complex response of the linear model at ``freqs_hz``.

    With ``dt`` the model is first discretized with a zero-order hold
    (:func:`control.sample_system`), which is how the simulator applies a
    command held over each control period and samples the output at the
    next step (one sample later, matching :func:`simulated_response`).
    """
    siso = output(sys, channel)
    if dt is not None:
        siso = control.sample_system(siso, dt, method="zoh")
    w = 2 * np.pi * np.asarray(freqs_hz, dtype=float)
    resp = siso.frequency_response(w)
    h = np.asarray(resp.complex).reshape(-1)
    if dt is not None:
        h = h * np.exp(1j * w * dt)  # the record pairs y[k+1] with u[k]
    return h
