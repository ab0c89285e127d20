"""Real measurements of a ZXF17-50 strain-wave actuator (harivin/harmonic-drive-actuator, MIT).

The files live in ``shared/real-data/harivin-zxf17/`` beside the checkout, or in
``$HDGYM_REAL_DATA`` (with their
``LICENSE``); they are read from there at run time, never copied. See that
folder's README for the columns.

:func:`load_friction_sweep` turns a ``friction_sweep_*.csv`` into an hdgym
:class:`~hdgym.record.Record` in SI units: the irregular ~5 ms log is
resampled onto its median step; ``output_angle`` = ``pos_deg`` in rad;
``motor_angle`` = 50 x ``output_angle`` (the rotor angle is not logged
separately, so kinematic error and wind-up cannot be told apart);
``motor_current`` = ``current_command`` = ``iq_A`` (the field-oriented
controller's measured q current; the position loop, not a current command,
decided it); the torque constant is the file's own ``torque_Nm / iq_A``.
Metadata: ``source``, ``licence``, ``loop: closed`` (so the workflow compares
in the torque domain), ``ratio``.

``python -m hdgym.discrepancy.realdata [--data DIR] [--out runs/real-data]``
writes the drive's parameter file and runs the workflow on the sweep.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import sys
from pathlib import Path

import numpy as np

from hdgym.params import (
    Amplifier,
    Compliance,
    Friction,
    FrictionSide,
    JointParams,
    Load,
    Motor,
    Sensors,
    Transmission,
    save,
)
from hdgym.record import Record, RecordError


def _data_dir() -> Path:
    """The real-data folder: $HDGYM_REAL_DATA, else ``shared/`` beside the checkout."""
    env = os.environ.get("HDGYM_REAL_DATA")
    if env:
        return Path(env)
    repo = Path(__file__).resolve().parents[2]
    return repo.parent / "shared" / "real-data" / "harivin-zxf17"


DATA = _data_dir()
RATIO = 50.0
SOURCE = ("harivin/harmonic-drive-actuator, folder data/ (MIT licence; see LICENSE in "
          "shared/real-data/harivin-zxf17)")


def _read_csv(path: Path) -> tuple[list[str], list[list[str]]]:
    try:
        with open(path, newline="") as fh:
            rows = list(csv.reader(fh))
    except OSError as exc:
        raise RecordError(f"{path}: cannot read: {exc.strerror or exc}") from None
    if len(rows) < 3:
        raise RecordError(f"{path}: {max(len(rows) - 1, 0)} data row(s); need at least 2")
    return [h.strip() for h in rows[0]], rows[1:]


def _column(path: Path, header: list[str], rows: list[list[str]], name: str) -> np.ndarray:
    if name not in header:
        raise RecordError(f"{path}: row 1 (header): missing column {name!r}; the file has "
                          f"{', '.join(header)}")
    j = header.index(name)
    out = np.empty(len(rows))
    for i, row in enumerate(rows):
        try:
            out[i] = float(row[j])
        except (ValueError, IndexError):
            raise RecordError(f"{path}: row {i + 2}, column {name!r}: "
                              f"{row[j] if j < len(row) else ''!r} is not a number") from None
        if not math.isfinite(out[i]):
            raise RecordError(f"{path}: row {i + 2}, column {name!r}: {out[i]!r} is not finite")
    return out


def torque_constant(path: Path) -> float:
    """Output-referred torque constant the controller assumed, N m/A (median torque/iq)."""
    header, rows = _read_csv(path)
    tq = _column(path, header, rows, "torque_Nm")
    iq = _column(path, header, rows, "iq_A")
    ok = np.abs(iq) > 0.2
    return float(np.median(tq[ok] / iq[ok]))


def load_friction_sweep(path: str | Path) -> Record:
    """A friction-sweep CSV as an hdgym Record (SI, uniform time step; see module docstring)."""
    path = Path(path)
    header, rows = _read_csv(path)
    t = _column(path, header, rows, "t_s")
    pos = np.radians(_column(path, header, rows, "pos_deg"))
    iq = _column(path, header, rows, "iq_A")
    fault = _column(path, header, rows, "fault") if "fault" in header else np.zeros(t.size)
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        raise RecordError(f"{path}: row {bad[0] + 3}, column 't_s': time {t[bad[0] + 1]!r} does "
                          f"not increase")
    dt = float(np.median(np.diff(t)))
    grid = t[0] + dt * np.arange(int(math.floor((t[-1] - t[0]) / dt)) + 1)
    out = np.interp(grid, t, pos)
    cur = np.interp(grid, t, iq)
    kt_out = torque_constant(path)
    meta = {"ratio": repr(RATIO), "configuration": "circular_spline", "locked_output": "false",
            "loop": "closed", "units": "SI", "source": f"{SOURCE}: {path.name}",
            "licence": "MIT", "torque_constant_output": f"{kt_out:.6g}",
            "faults": str(int(np.count_nonzero(fault)))}
    cols = {"time": grid - grid[0], "current_command": cur, "motor_current": cur,
            "motor_angle": RATIO * out, "output_angle": out,
            "motor_velocity": RATIO * np.gradient(out, dt)}
    return Record(cols, meta, str(path))


def breakaway_torque(path: str | Path) -> float | None:
    """Torque ceiling (output N m) in force when the breakaway ramp first moved more than 1 deg."""
    path = Path(path)
    header, rows = _read_csv(path)
    rev = _column(path, header, rows, "orbis_unwrapped_output_rev")
    step = _column(path, header, rows, "torque_step_Nm")
    moved = np.flatnonzero(np.abs(rev - rev[0]) * 360.0 > 1.0)
    return float(step[moved[0]]) if moved.size else None


def zxf17_params(kt_out: float) -> JointParams:
    """Base model of the ZXF17-50 actuator: Coulomb + viscous friction only.

    Only the ratio, the encoders and the torque constant come from the
    README/data; inertias, stiffness and amplifier are rough guesses (the
    slow sweeps cannot inform them), and the friction values are starting
    points for the fit, not the owner's numbers.
    """
    sources = {
        "transmission.n": "README: ZXF17 strain-wave gear, ratio 50:1",
        "motor.torque_constant": "median torque_Nm / iq_A of the sweep file, / 50 (motor side)",
        "motor.inertia": "guess (frameless motor rotor + wave generator); fitted",
        "load.inertia": "guess (output flange + 100 g arm); fitted",
        "compliance.stiffness": "guess for a size-17 strain-wave gear; not identifiable here",
        "friction.output.coulomb": "starting value for the fit",
        "friction.output.viscous": "starting value for the fit",
        "amplifier.current_limit": "README: torque cap 18 N m / torque constant",
        "sensors": "README: 14-bit absolute encoders on rotor and output",
    }
    return JointParams(
        motor=Motor(inertia=3e-5, torque_constant=kt_out / RATIO, back_emf_constant=kt_out / RATIO,
                    resistance=0.5),
        transmission=Transmission(n=RATIO, grounded="circular_spline"),
        compliance=Compliance(stiffness=1.0e4, model="linear"),
        load=Load(inertia=2e-3),
        amplifier=Amplifier(current_limit=18.0 / kt_out, voltage_limit=24.0),
        friction=Friction(output=FrictionSide(coulomb=3.0, breakaway=3.0, viscous=2.0)),
        sensors=Sensors(motor_counts=16384, output_counts=16384, torque_sensor=False),
        effects=("coulomb_friction", "viscous_friction"),
        name="zxf17-50", description="ZXF17-50 strain-wave actuator (harivin), base model",
        sources=sources,
    )


def main(argv: list[str] | None = None) -> int:
    from .report import write_report
    from .workflow import diagnose

    ap = argparse.ArgumentParser(prog="python -m hdgym.discrepancy.realdata",
                                 description="run the discrepancy workflow on the ZXF17 sweep")
    ap.add_argument("--data", default=str(DATA))
    ap.add_argument("--out", default="runs/real-data",
                    help="folder (default %(default)s; committed: --out results/real-data)")
    args = ap.parse_args(argv)
    data = Path(args.data)
    sweeps = sorted(data.glob("friction_sweep_*.csv"))
    if not sweeps:
        print(f"no friction_sweep_*.csv in {data}", file=sys.stderr)
        return 2
    rec = load_friction_sweep(sweeps[0])
    kt_out = float(rec.meta["torque_constant_output"])
    params = zxf17_params(kt_out)
    out = Path(args.out)
    # the two sweep cycles: fit on the first, validate on the second
    tm = float(rec.time[len(rec) // 2])
    train, val = rec.slice(None, tm), rec.slice(tm, None)
    train = Record(dict(train.columns), dict(train.meta),
                   f"{sweeps[0]} (first sweep cycle, t < {tm:.1f} s)")
    val = Record(dict(val.columns), dict(val.meta),
                 f"{sweeps[0]} (second sweep cycle, t >= {tm:.1f} s)")
    diag = diagnose(train, params, val, mode="inverse", fit_window=None)
    notes = _notes(diag, data, kt_out)
    notes.append("Base model: zxf17-50.toml in this folder (written by the same command); the "
                 "data are read from shared/real-data/harivin-zxf17 at run time (MIT "
                 "licence, LICENSE there), not copied.")
    write_report(diag, out, notes=notes,
                 title="Discrepancy report: ZXF17-50 friction sweep (real data)",
                 command="python -m hdgym.discrepancy.realdata")
    save(params, out / "zxf17-50.toml")
    print(f"missing effects: {diag.missing_effects or 'none'}; NMSE "
          f"{diag.nmse_before:.3g} -> {diag.nmse_after:.3g} %; wrote {out}/report.md")
    return 0


def _notes(diag, data: Path, kt_out: float) -> list[str]:
    from .registry import ANCHOR_FACTOR, get_value

    p = diag.after.params
    fo = p.friction.output
    notes = [
        f"Record: {len(diag.problem.record)} samples at {diag.problem.dt * 1e3:.2f} ms "
        f"(resampled from the irregular log); torque constant from the file "
        f"{kt_out:.3f} N m/A output-referred.",
        "Comparison in the torque domain (closed-loop record): the measured motion goes "
        "through the model's rigid-joint inverse dynamics and the predicted current is compared "
        "with iq while the output moves faster than 20 % of its typical speed (reversals and "
        "the pauses at the ends are left out, where friction is set-valued).",
        f"Fitted running (Coulomb) friction: {fo.coulomb:.2f} N m at the output "
        f"(owner: kinetic friction 4.1-4.4 N m at 0.05 output rev/s); viscous "
        f"{fo.viscous:.3g} N m s/rad"
        + (" (at the edge of the range the fit allows, the starting 2.0 divided by "
           f"{ANCHOR_FACTOR:g}: a sweep at one speed cannot separate viscous from Coulomb "
           "friction, so treat Coulomb + viscous x speed = "
           f"{fo.coulomb + fo.viscous * 2 * math.pi * 0.05:.2f} N m at 0.05 rev/s as the "
           "measured running friction)." if abs(fo.viscous * ANCHOR_FACTOR - 2.0) < 1e-6
           else "."),
        "Inertias are not informed by a slow sweep (accelerations are tiny once reversals "
        "are masked).",
    ]
    for k, r in enumerate(fo.ripple):
        notes.append(f"Friction ripple {k + 1}: {r.amplitude:.2f} N m at order {r.order:g} of the "
                     f"rotor (WG) angle, phase {math.degrees(r.phase):.0f} deg.")
    if "load_dependent_friction" in p.effects:
        notes.append(f"tooth_mu {get_value(p, 'friction.tooth_mu'):.3g}")
    ramps = sorted(data.glob("breakaway_ramp_*.csv"))
    if ramps:
        tb = breakaway_torque(ramps[0])
        if tb is not None:
            notes.append(f"Breakaway ramp file {ramps[0].name} (a different day): the output "
                         f"first moved more than 1 deg with the torque ceiling at {tb:.1f} N m, "
                         f"after creeping a few tenths of a degree at the step below; that is "
                         f"about the running friction of the sweep, not the owner's 'about 10 "
                         f"N m from rest' (which this file does not show). The file is not "
                         f"diagnosed (a stalled velocity loop, not a motion record); stiction "
                         f"cannot be tested on the sweep, whose reversals are masked.")
    notes += [
        "What these records cannot tell: the rotor angle is 50 x the output angle (no separate "
        "input encoder in the sweep), so kinematic error and wind-up are invisible and "
        "inseparable; there is no torque sensor (torque_Nm is K_t x iq), so stiffness and "
        "hysteresis cannot be identified; input- and output-side friction are one lumped "
        "output-referred friction; the amplifier never saturates in a slow sweep; gravity of "
        "the 100 g arm (<= 0.18 N m) is left in the friction.",
    ]
    return notes


if __name__ == "__main__":
    sys.exit(main())
