"""Analysis for the fidelity items: plain functions on arrays, reused by tests.

- :func:`ke_order_spectrum`: kinematic error against wave-generator angle (Tuttle §2.2);
- :func:`step_table` / :func:`starting_current`: batched current steps from rest (Tuttle §2.6);
- :func:`plateau_jump` / :func:`grows_smoothly`: a velocity plateau and its breakout;
- :func:`frequency_response` / :func:`resonance_peak`: H1 estimate and its peak;
- :func:`plateau_near` / :func:`run_up`: a plateau near a speed, and the torque
  fluctuation against speed pooled over the steps (resonant areas);
- :func:`loop_metrics`: hardening and hysteresis of a torque / wind-up loop.

Everything is deterministic.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal as sps

from hdgym.effects import flags_of
from hdgym.params import JointParams
from hdgym.physics import kernel
from hdgym.physics import layout as L
from hdgym.reproduce.common import within

# ===================================================================== (a) KE spectrum


@dataclass(frozen=True)
class OrderSpectrum:
    """Amplitude spectrum of a signal sampled at equal WG angle.

    Attributes:
        orders: cycles per WG revolution of each bin.
        amplitude: single-sided amplitude of each bin (units of the signal).
        signal: the detrended, resampled signal.
        wg_angle: the uniform WG-angle grid, rad.
        peak_to_peak: peak-to-peak of the signal band-limited to orders
            ``band`` (removes encoder quantization noise and drift).
        band: the order band used for ``peak_to_peak``.
    """

    orders: np.ndarray
    amplitude: np.ndarray
    signal: np.ndarray
    wg_angle: np.ndarray
    peak_to_peak: float
    band: tuple[float, float]

    def line(self, order: float, half_width: float = 0.25) -> float:
        """Amplitude of the line at ``order``: root-sum-square of the bins within ``half_width``.

        Summing the bins keeps a line's amplitude when it falls between bins
        or is split (tooth lines at ``2`` and ``2(1 -+ 1/ratio)``).
        """
        sel = np.abs(self.orders - order) <= half_width
        return float(np.sqrt(np.sum(self.amplitude[sel] ** 2)))


def ke_order_spectrum(motor_angle: np.ndarray, output_angle: np.ndarray, ratio: float,
                      points_per_rev: int = 256, band: tuple[float, float] = (0.5, 12.5)
                      ) -> OrderSpectrum:
    """Kinematic-error order spectrum (Tuttle §2.2, UNAL): resample, detrend, FFT.

    ``theta_err = motor_angle/ratio - output_angle`` is interpolated
    (``np.interp``) onto a uniform grid of WG angle spanning a whole number
    of WG revolutions, linearly detrended and Fourier transformed; orders
    are cycles per WG revolution.

    Args:
        motor_angle: WG angle, rad, increasing (quantized encoder samples are fine).
        output_angle: output angle, rad.
        ratio: motor angle per output angle.
        points_per_rev: samples per WG revolution of the grid.
        band: orders kept for the peak-to-peak value.

    Raises:
        ValueError: if the WG turns less than two revolutions or runs backwards.
    """
    th_m = np.asarray(motor_angle, dtype=float)
    err = th_m / ratio - np.asarray(output_angle, dtype=float)
    keep = np.concatenate([[True], np.diff(th_m) > 0])  # first sample of each new count
    th_m, err = th_m[keep], err[keep]
    if th_m.size < 4 or np.any(np.diff(th_m) <= 0):
        raise ValueError("ke_order_spectrum: motor_angle must increase")
    n_rev = int(math.floor((th_m[-1] - th_m[0]) / (2 * math.pi)))
    if n_rev < 2:
        raise ValueError(f"ke_order_spectrum: need at least 2 WG revolutions, got "
                         f"{(th_m[-1] - th_m[0]) / (2 * math.pi):.2f}")
    n = n_rev * points_per_rev
    grid = th_m[0] + np.arange(n) * (2 * math.pi * n_rev / n)
    sig = sps.detrend(np.interp(grid, th_m, err))
    spec = np.fft.rfft(sig)
    amp = np.abs(spec) * 2.0 / n
    amp[0] /= 2.0
    orders = np.arange(spec.size) / n_rev
    sel = (orders >= band[0]) & (orders <= band[1])
    lim = np.fft.irfft(np.where(sel, spec, 0.0), n)
    return OrderSpectrum(orders=orders, amplitude=amp, signal=sig, wg_angle=grid,
                         peak_to_peak=float(lim.max() - lim.min()), band=band)


def starting_current(p: JointParams, currents: np.ndarray | None = None, duration: float = 3.0,
                     min_speed: float = 3.0, max_speed: float = 60.0) -> float:
    """Smallest current that turns the WG slowly and steadily (``min_speed``-``max_speed`` rad/s).

    Runs a batch of constant currents (true states) and returns the first
    whose WG speed never drops to zero in the second half and whose mean
    speed lies in the band.
    """
    if currents is None:
        currents = p.amplifier.current_limit * np.geomspace(0.01, 1.0, 160)
    _, traces = step_table(p, currents, duration=duration, traces=True)
    half = traces.shape[0] // 2
    for k, c in enumerate(currents):
        w = traces[half:, k]
        if np.min(w) > 0 and min_speed <= np.mean(w) <= max_speed:
            return float(c)
    raise ValueError(f"{p.name}: no current in {currents[0]:.3g}-{currents[-1]:.3g} A turns the "
                     f"WG steadily at {min_speed}-{max_speed} rad/s")


# ===================================================================== (b) current steps


@dataclass(frozen=True)
class StepRuns:
    """Tuttle §2.6 current steps from rest: what each step did over its last ``average`` s.

    Attributes:
        currents: step currents, A.
        speed: mean WG speed, rad/s.
        torque_mean: mean flexspline torque (the torque sensor's reading), N m.
        torque_peak: largest |flexspline torque| in the window, N m.
        torque_std: standard deviation of the flexspline torque in the window, N m.
        wg_speed: WG speed of every step at every control period, rad/s, ``(n, n_currents)``.
        torque: flexspline torque likewise, N m.
        ctrl_dt: control period, s.
        inertial_peak: largest |J_o d(omega_o)/dt| in the window (the output's inertial
            torque over each control period, plus the load), N m.
    """

    currents: np.ndarray
    speed: np.ndarray
    torque_mean: np.ndarray
    torque_peak: np.ndarray
    torque_std: np.ndarray
    wg_speed: np.ndarray
    torque: np.ndarray
    ctrl_dt: float
    inertial_peak: np.ndarray | None = None


def step_runs(p: JointParams | list[JointParams], currents: np.ndarray | tuple[float, ...],
              duration: float = 4.0, average: float = 2.0) -> StepRuns:
    """Tuttle §2.6 current steps from rest, all in one batched kernel call per period.

    Args:
        p: the joint, or one joint per current.
        currents: step currents, A.
        duration: length of each step, s.
        average: the statistics are taken over the last ``average`` s.

    Raises:
        ValueError: joints that differ in control period or substeps, or a count mismatch.
        RuntimeError: a step diverged (names the current).
    """
    currents = np.asarray(currents, dtype=float)
    plist = p if isinstance(p, list) else [p] * currents.size
    if len(plist) != currents.size:
        raise ValueError("step_runs: one joint per current, or one joint for all")
    ps = np.stack([L.pack(q) for q in plist])
    fl = np.array([flags_of(q.effects) for q in plist], dtype=np.int64)
    dts = {q.integration.ctrl_dt for q in plist}
    subs = {int(q.integration.n_substeps) for q in plist}
    if len(dts) != 1 or len(subs) != 1:
        raise ValueError("step_runs: all joints must share ctrl_dt and n_substeps")
    dt, n_sub = dts.pop(), subs.pop()
    xs = L.initial_state(ps, fl)
    bad = np.zeros(currents.size, dtype=bool)
    zero = np.zeros(currents.size)
    n = int(round(duration / dt))
    start = n - int(round(average / dt))
    w = np.empty((n, currents.size))
    tk = np.empty((n, currents.size))
    wo = np.empty((n, currents.size))
    step = kernel.step_parallel if currents.size > 2 else kernel.step_serial
    for k in range(n):
        step(xs, ps, currents, zero, dt / n_sub, n_sub, fl, bad)
        if bad.any():
            raise RuntimeError(f"step_runs: diverged at t = {k * dt:.4g} s, current "
                               f"{currents[np.argmax(bad)]} A")
        w[k] = xs[:, L.W_M]
        tk[k] = xs[:, L.TK]
        wo[k] = xs[:, L.W_O]
    ww, tw = w[start:], tk[start:]
    j_o = np.array([q.load.inertia for q in plist])
    # the output's inertial torque per control period (from rest), plus the load
    acc = np.diff(np.vstack([np.zeros((1, currents.size)), wo]), axis=0)[start:] / dt
    inertial = j_o * acc + np.array([q.load.torque for q in plist])
    speed = ww.mean(axis=0)
    return StepRuns(currents=currents, speed=speed, torque_mean=tw.mean(axis=0),
                    torque_peak=np.abs(tw).max(axis=0), torque_std=tw.std(axis=0), wg_speed=w,
                    torque=tk, ctrl_dt=dt, inertial_peak=np.abs(inertial).max(axis=0))


def step_table(p: JointParams | list[JointParams], currents: np.ndarray | tuple[float, ...],
               duration: float = 4.0, average: float = 2.0, traces: bool = False
               ) -> tuple[np.ndarray, np.ndarray | None]:
    """Mean WG speed of each current step (:func:`step_runs`), rad/s.

    Returns:
        ``(mean WG speed per current in rad/s, traces (n_steps, n_currents) in rad/s or None)``.
    """
    runs = step_runs(p, currents, duration, average)
    return runs.speed, (runs.wg_speed if traces else None)


def plateau_near(currents: np.ndarray, speeds: np.ndarray, target: float, tol: float = 0.15,
                 spread: float = 0.10, min_len: int = 3) -> tuple[int, int] | None:
    """The longest run of consecutive currents whose speeds lie within ``spread`` of each
    other (max/min - 1) and whose mean lies within ``tol`` of ``target`` (a resonance
    plateau, Tuttle §2.6); None if no run has ``min_len`` currents."""
    sp = np.asarray(speeds, dtype=float)
    best: tuple[int, int] | None = None
    for a in range(sp.size):
        for b in range(a + min_len - 1, sp.size):
            s = sp[a: b + 1]
            if s.min() <= 0 or s.max() / s.min() - 1 > spread:
                break
            if within(s.mean(), target, tol) and (best is None or b - a > best[1] - best[0]):
                best = (a, b)
    return best


@dataclass(frozen=True)
class RunUp:
    """Torque fluctuation against WG speed, pooled over current steps (an order run-up).

    Attributes:
        speed: centre of each speed bin, °/s (bins with too few windows dropped).
        level: median over the bin's windows of the flexspline torque's standard
            deviation about its linear trend, N m.
    """

    speed: np.ndarray
    level: np.ndarray

    def prominence(self, target: float, tol: float = 0.15) -> tuple[float, float]:
        """``(height, speed)`` of the largest level within ``target (1 +- tol)`` over the
        higher of the two flanking minima (``target/2 .. target(1 - tol)`` and
        ``target(1 + tol) .. 2 target``), and the speed of that level; NaN when a
        flank or the window has no data."""
        sp, lv = self.speed, self.level
        win = (sp >= (1 - tol) * target) & (sp <= (1 + tol) * target)
        left = (sp >= 0.5 * target) & (sp < (1 - tol) * target)
        right = (sp > (1 + tol) * target) & (sp <= 2.0 * target)
        if not (win.any() and left.any() and right.any()):
            return math.nan, math.nan
        k = np.flatnonzero(win)[np.argmax(lv[win])]
        return float(lv[k] / max(lv[left].min(), lv[right].min())), float(sp[k])


def run_up(runs: StepRuns, window: float = 0.05, skip: float = 0.2, lo: float = 1000.0,
           hi: float = 60000.0, n_bins: int = 60, min_count: int = 3) -> RunUp:
    """Pool every step's record into a run-up curve (Tuttle §2.6: the joints pass through
    their resonant regions on the way up, and torque fluctuations grow there).

    Each step's record after ``skip`` s is cut into windows of ``window`` s; a window
    gives its mean WG speed and the standard deviation of the flexspline torque about
    the window's linear trend (so acceleration does not count). Windows are binned by
    speed (``n_bins`` geometric bins, ``lo``-``hi`` °/s) and each bin with at least
    ``min_count`` windows reports their median.
    """
    m = max(int(round(window / runs.ctrl_dt)), 3)
    k0 = int(round(skip / runs.ctrl_dt))
    w = np.degrees(runs.wg_speed[k0:])
    t = runs.torque[k0:]
    n_win = w.shape[0] // m
    w = w[:n_win * m].reshape(n_win, m, -1)
    t = t[:n_win * m].reshape(n_win, m, -1)
    x = np.arange(m) - (m - 1) / 2.0
    slope = np.einsum("kmc,m->kc", t, x) / float(x @ x)
    resid = t - t.mean(axis=1, keepdims=True) - slope[:, None, :] * x[None, :, None]
    speed = w.mean(axis=1).ravel()
    fluct = resid.std(axis=1).ravel()
    edges = np.geomspace(lo, hi, n_bins + 1)
    idx = np.digitize(speed, edges) - 1
    centres, levels = [], []
    for b in range(n_bins):
        sel = idx == b
        if sel.sum() >= min_count:
            centres.append(math.sqrt(edges[b] * edges[b + 1]))
            levels.append(float(np.median(fluct[sel])))
    return RunUp(np.array(centres), np.array(levels))


@dataclass(frozen=True)
class PlateauResult:
    """What :func:`plateau_jump` found (indices into the current/speed arrays).

    Attributes:
        plateau: (first, last) index of the longest run of consecutive
            currents in the window whose speeds lie within ``tol`` of each
            other (max/min - 1), or None.
        spread: max/min - 1 of that run.
        jump: index ``j`` of the first step ``j -> j+1`` at or after the
            plateau's last current whose speed rises by at least the jump
            threshold, or None.
        jump_ratio: speed[j+1]/speed[j] - 1 at that step.
    """

    plateau: tuple[int, int] | None
    spread: float
    jump: int | None
    jump_ratio: float

    @property
    def ok(self) -> bool:
        """A plateau followed by a jump."""
        return self.plateau is not None and self.jump is not None


def plateau_jump(currents: np.ndarray, speeds: np.ndarray, window: tuple[float, float] = (2.8, 4.0),
                 tol: float = 0.10, min_len: int = 3, jump: float = 0.30) -> PlateauResult:
    """Find a velocity plateau (Tuttle §2.6) and the jump where the joint breaks out.

    Args:
        currents: step currents, A, increasing.
        speeds: mean steady speeds, any unit (> 0).
        window: currents (A, inclusive) the plateau must lie in.
        tol: the plateau's speeds lie within ``tol`` of each other (max/min - 1).
        min_len: at least this many consecutive currents.
        jump: relative rise of the breakout step.
    """
    cur = np.asarray(currents, dtype=float)
    sp = np.asarray(speeds, dtype=float)
    if cur.shape != sp.shape:
        raise ValueError("plateau_jump: currents and speeds differ in length")
    idx = [i for i in range(cur.size) if window[0] - 1e-9 <= cur[i] <= window[1] + 1e-9]
    best: tuple[int, int] | None = None
    spread = math.inf
    for a in range(len(idx)):
        for b in range(a + min_len - 1, len(idx)):
            s = sp[idx[a]: idx[b] + 1]
            if s.min() <= 0:
                continue
            sprd = float(s.max() / s.min() - 1.0)
            longer = best is None or idx[b] - idx[a] > best[1] - best[0]
            tighter = best is not None and idx[b] - idx[a] == best[1] - best[0] and sprd < spread
            if sprd <= tol and (longer or tighter):
                best, spread = (idx[a], idx[b]), sprd
    if best is None:
        return PlateauResult(None, math.nan, None, math.nan)
    rise = sp[1:] / np.maximum(sp[:-1], 1e-300) - 1.0
    for j in range(best[1], sp.size - 1):
        if rise[j] >= jump:
            return PlateauResult(best, spread, j, float(rise[j]))
    return PlateauResult(best, spread, None, math.nan)


def grows_smoothly(speeds: np.ndarray, max_rise: float = 0.30, spike: float = 2.0
                   ) -> tuple[bool, float]:
    """Speed rises at every step, without a jump.

    A jump is a step that rises by ``max_rise`` or more *and* by more than
    ``spike`` times the median rise of the series: a speed curve that
    climbs steeply but evenly (falling friction at high speed) is smooth;
    an isolated leap out of a trap is not.

    Returns ``(smooth, largest relative rise)``.
    """
    sp = np.asarray(speeds, dtype=float)
    rise = sp[1:] / np.maximum(sp[:-1], 1e-300) - 1.0
    med = float(np.median(rise))
    jumps = (rise >= max_rise) & (rise > spike * med)
    return bool(np.all(rise > 0) and not np.any(jumps)), float(rise.max())


# ===================================================================== (c) resonance


def frequency_response(u: np.ndarray, y: np.ndarray, dt: float, nperseg: int = 2048
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """H1 estimate ``S_uy / S_uu`` and coherence (Welch, Hann, 50 % overlap).

    Returns ``(f in Hz, H complex, coherence)``.
    """
    fs = 1.0 / dt
    f, puu = sps.welch(u, fs=fs, nperseg=nperseg)
    _, puy = sps.csd(u, y, fs=fs, nperseg=nperseg)
    _, coh = sps.coherence(u, y, fs=fs, nperseg=nperseg)
    h = puy / np.where(puu > 0, puu, np.inf)
    return f, h, coh


def resonance_peak(f: np.ndarray, mag: np.ndarray, band: tuple[float, float] = (10.0, 200.0)
                   ) -> float:
    """Frequency of the largest ``mag`` in ``band``, refined by a parabola through 3 bins."""
    sel = np.flatnonzero((f >= band[0]) & (f <= band[1]))
    k = sel[np.argmax(mag[sel])]
    if 0 < k < f.size - 1:
        a, b, c = np.log(mag[k - 1: k + 2])
        den = a - 2 * b + c
        off = 0.5 * (a - c) / den if den != 0 else 0.0
        return float(f[k] + off * (f[1] - f[0]))
    return float(f[k])


# ===================================================================== (d) loop


@dataclass(frozen=True)
class LoopMetrics:
    """Hardening and hysteresis of a torque / wind-up loop.

    Attributes:
        k_low: incremental stiffness at |torque| < ``low`` x peak, N m/rad.
        k_high: incremental stiffness at |torque| > ``high`` x peak, N m/rad.
        hardening: k_high / k_low.
        area: enclosed area of the last full cycle, J (N m rad).
        branch_gap: mean torque difference loading - unloading branch at equal
            wind-up over the middle of the wind-up range, N m.
    """

    k_low: float
    k_high: float
    hardening: float
    area: float
    branch_gap: float


def loop_metrics(windup: np.ndarray, torque: np.ndarray, low: float = 0.25, high: float = 0.7
                 ) -> LoopMetrics:
    """Stiffness at low and high load, loop area and branch gap of a quasi-static loop.

    Incremental stiffness is the least-squares slope of torque on wind-up
    over the samples of each branch (loading, unloading separately, slopes
    averaged) whose |torque| is below ``low`` x or above ``high`` x the peak.
    """
    x = np.asarray(windup, dtype=float)
    t = np.asarray(torque, dtype=float)
    dx = np.gradient(x)
    peak = float(np.max(np.abs(t)))

    def slope(mask: np.ndarray) -> float:
        vals = []
        for branch in (dx > 0, dx < 0):
            for sign in (1.0, -1.0):
                m = mask & branch & (np.sign(t) == sign)
                if m.sum() > 5 and np.ptp(x[m]) > 0:
                    vals.append(np.polyfit(x[m], t[m], 1)[0])
        return float(np.mean(vals)) if vals else math.nan

    k_low = slope(np.abs(t) < low * peak)
    k_high = slope(np.abs(t) > high * peak)
    area = float(abs(np.trapezoid(t, x)))
    lo_x, hi_x = np.quantile(x, [0.3, 0.7])
    grid = np.linspace(lo_x, hi_x, 21)
    up, dn = dx > 0, dx < 0
    o_up, o_dn = np.argsort(x[up]), np.argsort(x[dn])
    t_up = np.interp(grid, x[up][o_up], t[up][o_up])
    t_dn = np.interp(grid, x[dn][o_dn], t[dn][o_dn])
    return LoopMetrics(k_low, k_high, k_high / k_low, area, float(np.mean(t_up - t_dn)))
