"""Numerical health: substep convergence per preset and a long soak run.

* :func:`convergence` runs one standard excitation at several substep counts
  and reports the error against a run with a much finer step, so a user can
  see which ``n_substeps`` a drive needs.
* :func:`soak` runs a joint for a million control periods (chunked inside
  the compiled loop) and reports state bounds, energy bookkeeping and process
  memory at the start and end: no drift, no growth.
"""

from __future__ import annotations

import resource
import time
from pathlib import Path

import numpy as np

from hdgym.commands import command_signal
from hdgym.effects import flags_of
from hdgym.page_changes import moved_section
from hdgym.params import JointParams, atomic_write_text
from hdgym.physics import kernel
from hdgym.physics import layout as L

SUBSTEPS = (1, 2, 5, 10, 20, 40)


def excitation(p: JointParams, n_steps: int, seed: int) -> np.ndarray:
    """Random current at 40 % of the amplifier limit plus a 30 % mean drive, A."""
    t = np.arange(n_steps) * p.integration.ctrl_dt
    i_max = p.amplifier.current_limit
    cutoff = min(50.0, 0.2 / p.integration.ctrl_dt)
    rng = np.random.default_rng(seed)
    return 0.3 * i_max + command_signal(f"random:{0.4 * i_max}:{cutoff}", t, rng)


def _angles(p: JointParams, u: np.ndarray, n_sub: int) -> np.ndarray:
    row = L.pack(p)
    flags = flags_of(p.effects)
    x = L.initial_state(row[None, :], flags)[0]
    out = np.empty((u.size, L.N_STATE))
    bad = kernel.run_open_loop(x, row, u, np.zeros_like(u), p.integration.ctrl_dt / n_sub,
                               n_sub, flags, out)
    if bad >= 0:
        out[bad:] = np.nan
    return out[:, [L.TH_M, L.TH_O, L.TK]]


def convergence(p: JointParams, duration: float = 1.0, seed: int = 0,
                substeps: tuple[int, ...] = SUBSTEPS, reference: int = 160) -> list[dict]:
    """Error of motor angle, output angle and flexspline torque against ``reference``
    substeps, for each count in ``substeps`` (relative to each signal's range)."""
    n = int(round(duration / p.integration.ctrl_dt))
    u = excitation(p, n, seed)
    ref = _angles(p, u, reference)
    span = np.ptp(ref, axis=0) + 1e-300
    rows = []
    for n_sub in substeps:
        got = _angles(p, u, n_sub)
        err = np.max(np.abs(got - ref), axis=0) / span
        rms = np.sqrt(np.mean((got - ref) ** 2, axis=0)) / span
        rows.append({"n_substeps": n_sub, "dt": p.integration.ctrl_dt / n_sub,
                     "motor_angle": float(err[0]), "output_angle": float(err[1]),
                     "torque": float(err[2]), "torque_rms": float(rms[2]),
                     "diverged": bool(np.isnan(err).any())})
    return rows


def _rss_mb() -> float:
    """Resident memory of this process now, MiB (from /proc; peak RSS elsewhere)."""
    try:
        with open("/proc/self/statm") as fh:
            pages = int(fh.read().split()[1])
        return pages * resource.getpagesize() / 2**20
    except OSError:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def soak(p: JointParams, n_steps: int = 1_000_000, chunk: int = 50_000, seed: int = 0) -> dict:
    """Run ``n_steps`` control periods on a slowly varying random current.

    Returns state bounds over the first and the last chunk, the energy
    balance residual relative to the energy through the joint, wall time and
    peak memory at start and end.
    """
    row = L.pack(p)
    flags = flags_of(p.effects)
    x = L.initial_state(row[None, :], flags)[0]
    u = excitation(p, chunk, seed)
    out = np.empty((chunk, L.N_STATE))
    mem0 = _rss_mb()
    t0 = time.perf_counter()
    first = last = None
    done = 0
    k = 0
    while done < n_steps:
        m = min(chunk, n_steps - done)
        # alternate sign so the joint goes back and forth instead of winding up forever
        cmd = u[:m] if k % 2 == 0 else -u[:m]
        bad = kernel.run_open_loop(x, row, cmd, np.zeros(m), p.integration.ctrl_dt /
                                   p.integration.n_substeps, p.integration.n_substeps, flags,
                                   out[:m])
        if bad >= 0:
            raise RuntimeError(f"soak of {p.name} diverged at step {done + bad}")
        bounds = {"motor_velocity": float(np.max(np.abs(out[:m, L.W_M]))),
                  "output_torque": float(np.max(np.abs(out[:m, L.TK]))),
                  "torsion": float(np.max(np.abs(out[:m, L.DTH]))),
                  "current": float(np.max(np.abs(out[:m, L.CUR])))}
        first = bounds if first is None else first
        last = bounds
        done += m
        k += 1
    return {"preset": p.name, "steps": done, "seconds": time.perf_counter() - t0,
            "first": first, "last": last, "memory_start_mb": mem0, "memory_end_mb": _rss_mb(),
            "finite": bool(np.all(np.isfinite(x)))}


def write_table(out: Path, quick: bool = False) -> None:
    """Convergence table of every preset as markdown (``hdgym numerics``)."""
    from hdgym.params import preset, preset_names
    from hdgym.progress import bar

    cmd = "hdgym numerics" + (" --quick" if quick else "") + f" --out {out}"
    lines = ["# Substep convergence", "",
             f"Regenerate with `{cmd}`. Each preset runs {0.5 if quick else 2.0} s of random "
             "current (30 % of the amplifier limit mean, 40 % RMS) with every effect on; the "
             "error is the largest deviation from a run at 160 substeps per control period, "
             "relative to the signal's range (torque also as RMS). Stick-slip events make the "
             "error non-monotone: a switching instant moves by up to one substep, and after a "
             "slip the two runs can part for a while. *Needs* is the smallest count whose "
             "torque RMS error is below 1 %.", ""]
    for name in bar(preset_names(), "numerics", unit="preset"):
        p = preset(name)
        rows = convergence(p, duration=0.5 if quick else 2.0)
        ok = [r["n_substeps"] for r in rows if not r["diverged"] and r["torque_rms"] < 0.01]
        needs = f"needs {min(ok)}" if ok else f"needs more than {rows[-1]['n_substeps']}"
        lines += [f"## {name} (default n_substeps = {p.integration.n_substeps}, "
                  f"ctrl_dt = {p.integration.ctrl_dt:g} s; {needs})", "",
                  "| n_substeps | substep (s) | motor angle | output angle | flexspline torque "
                  "| torque RMS |", "|---|---|---|---|---|---|"]
        for r in rows:
            if r["diverged"]:
                lines.append(f"| {r['n_substeps']} | {r['dt']:.3g} | diverged | diverged | "
                             "diverged | diverged |")
            else:
                lines.append(f"| {r['n_substeps']} | {r['dt']:.3g} | {r['motor_angle']:.2e} | "
                             f"{r['output_angle']:.2e} | {r['torque']:.2e} | "
                             f"{r['torque_rms']:.2e} |")
        lines.append("")
    lines += _step_table_section(quick)
    text = "\n".join(lines)
    moved = moved_section(Path(out), text)  # what this run changed against the page it replaces
    atomic_write_text(out, text + ("\n" + moved if moved else ""))


def _step_table_section(quick: bool) -> list[str]:
    """Tuttle's current-step table (fidelity item b) at several substep counts.

    The random-excitation errors above are a strict test (stick-slip and
    resonance make nearby trajectories part); this shows whether the
    quantity the fidelity page asserts moves with the step.
    """
    from hdgym.params import preset
    from hdgym.reproduce import step_table

    currents = np.round(np.arange(1.6, 6.01, 0.8 if quick else 0.4), 2)
    p = preset("tuttle-joint1")
    lines = ["## tuttle-joint1: Tuttle's current-step table against the substep", "",
             "Mean input speed over the last 2 s of 4 s current steps from rest (°/s), as in "
             "`hdgym reproduce tuttle` item T2.", "",
             "| n_substeps | " + " | ".join(f"{c:g} A" for c in currents) + " |",
             "|---|" + "---|" * len(currents)]
    for n_sub in (5, 10, 20, 40):
        speeds, _ = step_table(p.set("integration.n_substeps", n_sub), currents)
        lines.append(f"| {n_sub} | " + " | ".join(f"{v:.0f}" for v in np.degrees(speeds)) + " |")
    return lines + [""]
