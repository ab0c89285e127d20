"""The discrepancy workflow on real ZXF17-50 sweeps: a per-file table and a cross-record table.

``python -m hdgym.discrepancy.realdata [PATH ...] [--out DIR] [--quick]``

Each PATH is a ``friction_sweep_*.csv`` or a folder (every sweep in it); default: the files
shipped in ``hdgym/discrepancy/data/zxf17`` (see ``ORIGIN.md`` there). Per file
(:func:`diagnose_sweep`): the fault-flagged rows are dropped from the comparison and
reported, the sweep is split by its legs, the workflow fits on the first out-and-back cycle
and validates on the second (labels name the legs and their times). Across files
(:func:`cross_record`): the model fitted on one run is validated on another with only the
declared per-run nuisances re-estimated (:data:`NUISANCES`: the rotor-angle zero, because the
logged angles count from the start of each run). With one file there is no second run; the
cross-record table then uses a stand-in built from the same log: its second cycle from the
middle of a leg on, with its angles re-zeroed there, as a run started at another rotor angle
would log it (labelled as such).

Every number in the notes is computed from the data by this command. Nothing is written
unless ``--out`` is given.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import minimize_scalar

from hdgym.files import atomic_write_text, check_out
from hdgym.params import JointParams, save
from hdgym.record import Record

from .diagnosis import Diagnosis
from .paths import get_value, set_values
from .problem import Problem
from .zxf17 import (
    DATA,
    FAULT_MARGIN,
    Sweep,
    breakaway_torque,
    display_name,
    read_sweep,
    sweep_files,
)
from .zxf17 import load_friction_sweep as load_friction_sweep
from .zxf17 import zxf17_params as zxf17_params

NUISANCES = {"rotor_zero": "rotor-angle zero, rad: the logged angles count from the start of "
                           "each run, so a position-dependent term fitted on one run is shifted "
                           "on another by an unknown rotor angle"}
"""Per-run nuisances: re-estimated on each run, never carried over."""


@dataclass
class SweepResult:
    """One file diagnosed: the sweep, its diagnosis and the parts used."""

    sweep: Sweep
    diagnosis: Diagnosis
    train: str
    validate: str


def diagnose_sweep(sweep: Sweep, quick: bool = False) -> SweepResult:
    """Fit on the first out-and-back cycle, validate on the second (or on the second leg)."""
    from .workflow import diagnose

    parts = sweep.cycles()
    if len(parts) < 2:
        parts = [(f"leg {g.number} ({g.t0:.1f}-{g.t1:.1f} s)", g.t0, g.t1) for g in sweep.legs]
    if len(parts) < 2:
        raise ValueError(f"{sweep.name}: {len(sweep.legs)} sweep leg(s) of at least 2 s; need "
                         f"two to fit on one and validate on the other")
    train = sweep.part(*parts[0])
    val = sweep.part(*parts[1])
    params = zxf17_params(sweep.torque_constant)
    diag = diagnose(train, params, val, mode="inverse", fit_window=None, quick=quick)
    return SweepResult(sweep, diag, parts[0][0], parts[1][0])


def shift_rotor(p: JointParams, phi: float) -> JointParams:
    """``p`` with the rotor-angle zero moved by ``phi`` rad (input-frame ripple phases)."""
    values = {}
    for side in ("input", "output"):
        for k, r in enumerate(getattr(p.friction, side).ripple):
            if r.frame == "input":
                values[f"friction.{side}.ripple[{k}].phase"] = r.phase + r.order * phi
    return set_values(p, values) if values else p


def rotor_zero(problem: Problem, p: JointParams) -> tuple[float, float]:
    """The rotor-angle zero (rad) that fits ``p`` best to ``problem``, and the NMSE there.

    A grid of 72 angles over one rotor turn, then a bounded scalar refinement.
    """
    grid = np.linspace(0.0, 2 * math.pi, 72, endpoint=False)
    costs = [problem.nmse(shift_rotor(p, g))["mean"] for g in grid]
    g0 = float(grid[int(np.argmin(costs))])
    step = grid[1] - grid[0]
    opt = minimize_scalar(lambda x: problem.nmse(shift_rotor(p, x))["mean"],
                          bounds=(g0 - step, g0 + step), method="bounded",
                          options={"xatol": 1e-3})
    phi = float(opt.x) if opt.fun < min(costs) else g0
    phi = (phi + math.pi) % (2 * math.pi) - math.pi
    return phi, float(problem.nmse(shift_rotor(p, phi))["mean"])


def stand_in(sweep: Sweep, at_deg: float = 80.0) -> tuple[str, Record, float]:
    """A second run made from one log: from where its second cycle first passes ``at_deg``
    (output degrees) to the end, with every angle re-zeroed there (see the module docstring).

    Returns the label, the record and the rotor-angle zero it moved (rad, in (-pi, pi]).
    """
    cyc = sweep.cycles()
    t0 = cyc[1][1] if len(cyc) > 1 else sweep.legs[-1].t0
    rec = sweep.record.slice(t0, None)
    out = np.asarray(rec.output_angle)
    k = int(np.argmax(np.degrees(out) >= at_deg)) if np.any(np.degrees(out) >= at_deg) else 0
    rec = rec.slice(float(rec.time[k]), None)
    cols = dict(rec.columns)
    o0, m0 = float(cols["output_angle"][0]), float(cols["motor_angle"][0])
    cols["output_angle"] = cols["output_angle"] - o0
    cols["motor_angle"] = cols["motor_angle"] - m0
    meta = dict(rec.meta)
    meta["angle_reference"] = (f"angles re-zeroed at t = {float(rec.time[0]):.2f} s of "
                               f"{sweep.path.name} (output {math.degrees(o0):.1f} deg)")
    label = (f"stand-in run: {sweep.name} from t = {float(rec.time[0]):.1f} s, angles "
             f"re-zeroed at output {math.degrees(o0):.1f} deg (rotor zero moved by "
             f"{math.degrees(m0) % 360:.1f} deg)")
    known = (m0 + math.pi) % (2 * math.pi) - math.pi
    return label, Record(cols, meta, label), known


def cross_record(results: list[SweepResult]) -> list[dict]:
    """Fit on one run, validate on another; only :data:`NUISANCES` re-estimated.

    Returns one row per ordered pair: the NMSE on the validation run of the base fit, the
    fitted model as it is, and with the rotor-angle zero re-estimated; the share of the gap
    (base fit against the run's own diagnosis) each recovers.
    """
    runs: list[tuple[str, Record, SweepResult | None]] = [
        (r.sweep.name, r.sweep.record, r) for r in results]
    known = 0.0
    if len(runs) == 1:
        label, rec, known = stand_in(results[0].sweep)
        runs.append((label, rec, None))
    rows = []
    for name_a, _, ra in runs:
        if ra is None:
            continue
        for name_b, rec_b, rb in runs:
            if name_b == name_a:
                continue
            d = ra.diagnosis
            prob = Problem(rec_b, d.before.params, mode="inverse", channels=d.channels)
            base = prob.nmse(d.before.params)["mean"]
            as_fit = prob.nmse(d.after.params)["mean"]
            phi, rezero = rotor_zero(prob, d.after.params)
            # the gap closes at the run's own diagnosis; for the stand-in, at the fitted model
            # with the rotor zero the stand-in was built with
            own = (prob.nmse(rb.diagnosis.after.params)["mean"] if rb is not None
                   else prob.nmse(shift_rotor(d.after.params, known))["mean"])
            gap = base - own
            rows.append({"fit": name_a, "validate": name_b, "base": base, "as_fitted": as_fit,
                         "rotor_zero_deg": math.degrees(phi), "rezeroed": rezero, "own": own,
                         "recovered_as_fitted": (base - as_fit) / gap if gap > 0 else None,
                         "recovered_rezeroed": (base - rezero) / gap if gap > 0 else None,
                         "known_zero_deg": None if rb is not None else math.degrees(known)})
    return rows


def _ripples(p: JointParams) -> list[tuple[float, float, float]]:
    return [(r.order, r.amplitude, r.phase) for r in p.friction.output.ripple]


def per_file_table(results: list[SweepResult]) -> str:
    lines = ["| file | legs | fault rows dropped | fit on | validate on | effects found | "
             "Coulomb N m | viscous N m s/rad | ripple (order: N m @ deg) | NMSE before % | "
             "NMSE after % |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        d, p = r.diagnosis, r.diagnosis.after.params
        fo = p.friction.output
        rip = ", ".join(f"{o:g}: {a:.2f} @ {math.degrees(ph) % 360:.0f}"
                        for o, a, ph in _ripples(p)) or "-"
        lines.append(f"| {r.sweep.name} | {len(r.sweep.legs)} | {r.sweep.fault_rows} | "
                     f"{r.train} | {r.validate} | {', '.join(d.missing_effects) or 'none'} | "
                     f"{fo.coulomb:.2f} | {fo.viscous:.3g} | {rip} | {d.nmse_before:.3g} | "
                     f"{d.nmse_after:.3g} |")
    return "\n".join(lines)


def cross_table(rows: list[dict]) -> str:
    def pct(x):
        return "-" if x is None else f"{100 * x:.0f} %"

    lines = ["| fitted on | validated on | NMSE base fit % | as fitted % | rotor zero "
             "re-estimated % (zero, deg) | gap recovered as fitted | gap recovered re-zeroed |",
             "|---|---|---|---|---|---|---|"]
    for c in rows:
        lines.append(f"| {c['fit']} | {c['validate']} | {c['base']:.3g} | {c['as_fitted']:.3g} "
                     f"| {c['rezeroed']:.3g} ({c['rotor_zero_deg']:.0f}) | "
                     f"{pct(c['recovered_as_fitted'])} | {pct(c['recovered_rezeroed'])} |")
    return "\n".join(lines)


def notes(r: SweepResult) -> list[str]:
    """Notes for one file's report, every number computed here."""
    from .registry import ANCHOR_FACTOR

    d, sw = r.diagnosis, r.sweep
    p = d.after.params
    fo = p.friction.output
    prob = d.problem
    w_out = np.abs(prob.w_o[prob.mask]) if prob.mask is not None else np.abs(prob.w_o)
    speed = float(np.median(w_out))
    running = fo.coulomb + fo.viscous * speed
    out = [
        f"Record: {sw.name}, {len(sw.record)} samples at {prob.dt * 1e3:.2f} ms (resampled from "
        f"the irregular log), {len(sw.legs)} legs; torque constant from the file "
        f"{sw.torque_constant:.3f} N m/A output-referred. Fitted on {r.train}, validated on "
        f"{r.validate}.",
        "Comparison in the torque domain (closed-loop record): the measured motion goes "
        "through the model's rigid-joint inverse dynamics and the predicted current is compared "
        "with iq while the output moves faster than 20 % of its typical speed (reversals and "
        "the pauses at the ends are left out, where friction is set-valued).",
    ]
    if sw.faults:
        out.append("Rows flagged with a fault code are not compared (nor "
                   f"{1e3 * FAULT_MARGIN:.0f} ms around them): " + "; ".join(
                       f"code {f.code}: {len(f.rows)} rows between t = {min(f.times):.2f} and "
                       f"{max(f.times):.2f} s" for f in sw.faults) + ".")
    viscous_edge = any(abs(fo.viscous - v0 * f) <= 1e-6 * v0
                       for v0 in (d.before.params.friction.output.viscous,)
                       for f in (1 / ANCHOR_FACTOR, ANCHOR_FACTOR))
    out.append(f"Fitted running friction at the output: Coulomb {fo.coulomb:.2f} N m, viscous "
               f"{fo.viscous:.3g} N m s/rad; at the median compared output speed "
               f"{speed:.3f} rad/s ({speed / (2 * math.pi):.3f} rev/s) that is {running:.2f} N m"
               + (" (the viscous coefficient sits at the edge of its range: a sweep at one speed "
                  "cannot separate viscous from Coulomb friction, only their sum at that speed)"
                  if viscous_edge else "") + ".")
    for k, (o, a, ph) in enumerate(_ripples(p)):
        out.append(f"Friction ripple {k + 1}: {a:.2f} N m at order {o:g} of the rotor (WG) "
                   f"angle, phase {math.degrees(ph):.0f} deg; angle reference: "
                   f"{sw.record.meta.get('angle_reference', 'the start of the run')}.")
    if "load_dependent_friction" in p.effects:
        out.append(f"tooth_mu {get_value(p, 'friction.tooth_mu'):.3g}")
    ramps = sorted(sw.path.parent.glob("breakaway_ramp_*.csv"))
    if ramps:
        tb = breakaway_torque(ramps[0])
        if tb is not None:
            out.append(f"Breakaway ramp {display_name(ramps[0])} (another day): the output first "
                       f"moved more than 1 deg with the torque ceiling at {tb:.1f} N m, "
                       f"{tb / running:.2f} x the running friction fitted here. The file is not "
                       "diagnosed (a stalled velocity loop, not a motion record); stiction "
                       "cannot be tested on the sweep, whose reversals are masked.")
    out.append("What these records cannot tell: the rotor angle is 50 x the output angle (no "
               "separate input encoder in the sweep), so kinematic error and wind-up are "
               "invisible and inseparable; there is no torque sensor (torque_Nm is K_t x iq), so "
               "stiffness and hysteresis cannot be identified; input- and output-side friction "
               "are one lumped output-referred friction; the amplifier never saturates in a "
               "slow sweep.")
    return out


def main(argv: list[str] | None = None) -> int:
    from .report import write_report

    ap = argparse.ArgumentParser(prog="python -m hdgym.discrepancy.realdata",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("paths", nargs="*", help="sweep files or folders (default: the shipped "
                                              "ZXF17 data)")
    ap.add_argument("--out", default=None, help="write the reports and tables here")
    ap.add_argument("--quick", action="store_true", help="fewer least-squares iterations")
    args = ap.parse_args(argv)
    try:
        if args.out:
            check_out(args.out, args.quick)
        files = sweep_files(args.paths or [DATA])
        results = [diagnose_sweep(read_sweep(f), quick=args.quick) for f in files]
    except ValueError as exc:
        print(f"realdata: {exc}", file=sys.stderr)
        return 2
    cross = cross_record(results)
    cmd = "python -m hdgym.discrepancy.realdata" + (" --quick" if args.quick else "")
    text = "\n".join([
        "# Real data: ZXF17-50 friction sweeps", "",
        f"Generated by `{cmd}" + (f" --out {args.out}`." if args.out else "`."), "",
        "## Per file", "", per_file_table(results), "",
        "## Across runs", "",
        "Fitted on one run, validated on another; only the declared per-run nuisances are "
        f"re-estimated ({'; '.join(f'{k}: {v}' for k, v in NUISANCES.items())}). *Gap* = NMSE "
        "of the base fit minus that of the run's own diagnosis (for the stand-in run: of the "
        "fitted model with the rotor zero the stand-in was made with).", "", cross_table(cross), "",
    ])
    print(text)
    if args.out:
        out = Path(args.out)
        for r in results:
            sub = out / r.sweep.path.stem if len(results) > 1 else out
            write_report(r.diagnosis, sub, notes=notes(r),
                         title=f"Discrepancy report: ZXF17-50 {r.sweep.path.stem} (real data)",
                         command=f"{cmd} --out {args.out}")
            save(zxf17_params(r.sweep.torque_constant), sub / "zxf17-50.toml")
        atomic_write_text(out / "tables.md", text + "\n")
        print(f"wrote {out}/tables.md and the report(s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
