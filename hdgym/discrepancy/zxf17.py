"""Read the ZXF17-50 real measurements shipped in ``data/zxf17/`` (see ``ORIGIN.md`` there).

:func:`read_sweep` turns a ``friction_sweep_*.csv`` into a :class:`Sweep`: an hdgym
:class:`~hdgym.record.Record` in SI units plus its legs and the rows the drive flagged with
a fault code. The irregular ~5 ms log is resampled onto its median step; ``output_angle`` =
``pos_deg`` in rad; ``motor_angle`` = 50 x ``output_angle`` (the rotor angle is not logged
separately, so kinematic error and wind-up cannot be told apart); ``motor_current`` =
``current_command`` = ``iq_A`` (the field-oriented controller's measured q current: the
position loop, not a current command, decided it); the torque constant is the file's own
``torque_Nm / iq_A``. Metadata: ``source``, ``licence``, ``loop: closed`` (the workflow
compares in the torque domain), ``ratio``, ``angle_reference`` (angles count from the first
sample of the run) and ``exclude`` (time spans not compared: the fault-flagged rows, widened
by :data:`FAULT_MARGIN`; see :class:`hdgym.discrepancy.problem.Problem`).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
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
)
from hdgym.record import Record, RecordError

DATA = Path(__file__).resolve().parent / "data" / "zxf17"
"""The shipped files (MIT licence beside them)."""
RATIO = 50.0
REPO = Path(__file__).resolve().parents[2]
ORIGIN = "harivin/harmonic-drive-actuator, folder data/ (MIT licence)"
FAULT_MARGIN = 0.05
"""Seconds on each side of a fault-flagged row that are not compared either (the filter and
the derivatives reach that far)."""
MIN_LEG = 2.0
"""A leg shorter than this (s) is not a sweep leg (the one-row end marker of a log)."""


def display_name(path: str | Path) -> str:
    """``path`` relative to the repository when it lies inside it, else its file name."""
    p = Path(path).resolve()
    try:
        return str(p.relative_to(REPO))
    except ValueError:
        return p.name


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


@dataclass(frozen=True)
class Leg:
    """One leg of a sweep: its number, time span (s, record time) and target (output deg)."""

    number: int
    t0: float
    t1: float
    target_deg: float


@dataclass(frozen=True)
class Fault:
    """Fault-flagged rows: the code and the file rows (1-based, header = row 1) and times."""

    code: int
    rows: tuple[int, ...]
    times: tuple[float, ...]


@dataclass
class Sweep:
    """A friction sweep read from its CSV (see the module docstring)."""

    path: Path
    record: Record
    legs: list[Leg]
    faults: list[Fault]
    torque_constant: float
    """Output-referred torque constant the controller assumed, N m/A (median torque/iq)."""

    @property
    def name(self) -> str:
        return display_name(self.path)

    @property
    def fault_rows(self) -> int:
        return sum(len(f.rows) for f in self.faults)

    def cycles(self) -> list[tuple[str, float, float]]:
        """Consecutive pairs of legs (out and back) as ``(label, t0, t1)``, record time (s)."""
        out = []
        for a, b in zip(self.legs[0::2], self.legs[1::2], strict=False):
            out.append((f"legs {a.number}-{b.number} ({a.t0:.1f}-{b.t1:.1f} s)", a.t0, b.t1))
        return out

    def part(self, label: str, t0: float, t1: float) -> Record:
        """The samples ``t0 <= t <= t1`` as a record named after the file and ``label``."""
        dt = float(self.record.dt)
        rec = self.record.slice(t0, t1 + 0.5 * dt)
        return Record(dict(rec.columns), dict(rec.meta), f"{self.name}, {label}")


def read_sweep(path: str | Path) -> Sweep:
    """A friction-sweep CSV as a :class:`Sweep` (SI record, legs, fault rows)."""
    path = Path(path)
    header, rows = _read_csv(path)
    t = _column(path, header, rows, "t_s")
    pos = np.radians(_column(path, header, rows, "pos_deg"))
    iq = _column(path, header, rows, "iq_A")
    tq = _column(path, header, rows, "torque_Nm")
    leg = _column(path, header, rows, "leg") if "leg" in header else np.ones(t.size)
    tgt = _column(path, header, rows, "tgt_deg") if "tgt_deg" in header else np.zeros(t.size)
    fault = _column(path, header, rows, "fault") if "fault" in header else np.zeros(t.size)
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        raise RecordError(f"{path}: row {bad[0] + 3}, column 't_s': time {t[bad[0] + 1]!r} does "
                          f"not increase")
    ok = (np.abs(iq) > 0.2) & (fault == 0)
    if not ok.any():
        raise RecordError(f"{path}: column 'iq_A': no fault-free row with |iq| > 0.2 A to read "
                          f"the torque constant from")
    kt_out = float(np.median(tq[ok] / iq[ok]))
    dt = float(np.median(np.diff(t)))
    grid = t[0] + dt * np.arange(int(math.floor((t[-1] - t[0]) / dt)) + 1)
    # fault rows are not compared (their angles still carry the motion across the gap)
    faults = []
    for code in sorted({int(c) for c in fault[fault != 0]}):
        idx = np.flatnonzero(fault == code)
        faults.append(Fault(code, tuple(int(i) + 2 for i in idx), tuple(float(t[i] - t[0])
                                                                     for i in idx)))
    spans = _spans([x for f in faults for x in f.times], FAULT_MARGIN)
    legs = []
    edges = np.flatnonzero(np.diff(leg) != 0) + 1
    for a, b in zip(np.r_[0, edges], np.r_[edges, t.size], strict=True):
        t0, t1 = float(t[a] - t[0]), float(t[b - 1] - t[0])
        if t1 - t0 >= MIN_LEG:
            legs.append(Leg(int(leg[a]), t0, t1, float(tgt[a])))
    meta = {"ratio": repr(RATIO), "configuration": "circular_spline", "locked_output": "false",
            "loop": "closed", "units": "SI", "source": f"{ORIGIN}: {path.name}",
            "licence": "MIT", "torque_constant_output": f"{kt_out:.6g}",
            "faults": str(int(np.count_nonzero(fault))),
            "angle_reference": f"angles count from the first sample of {path.name}",
            "exclude": ";".join(f"{a:.4f}:{b:.4f}" for a, b in spans)}
    cur = np.interp(grid, t, iq)
    out = np.interp(grid, t, pos)
    cols = {"time": grid - grid[0], "current_command": cur, "motor_current": cur,
            "motor_angle": RATIO * out, "output_angle": out,
            "motor_velocity": RATIO * np.gradient(out, dt)}
    rec = Record(cols, meta, display_name(path))
    return Sweep(path, rec, legs, faults, kt_out)


def _spans(times: list[float], margin: float) -> list[tuple[float, float]]:
    """Merged ``[t - margin, t + margin]`` spans around ``times`` (s)."""
    out: list[list[float]] = []
    for x in sorted(times):
        if out and x - margin <= out[-1][1]:
            out[-1][1] = x + margin
        else:
            out.append([x - margin, x + margin])
    return [(a, b) for a, b in out]


def load_friction_sweep(path: str | Path) -> Record:
    """The whole sweep as a record (see :func:`read_sweep`)."""
    return read_sweep(path).record


def sweep_files(paths: list[str | Path]) -> list[Path]:
    """Files named in ``paths``; a folder stands for every ``friction_sweep_*.csv`` in it.

    Raises:
        ValueError: a path that does not exist, or no sweep at all (naming the paths).
    """
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            found = sorted(p.glob("friction_sweep_*.csv"))
            if not found:
                raise ValueError(f"{p}: no friction_sweep_*.csv in this folder")
            out += found
        elif p.is_file():
            out.append(p)
        else:
            raise ValueError(f"{p}: no such file or folder")
    if not out:
        raise ValueError("no sweep file given")
    return list(dict.fromkeys(out))


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
    data and its description; inertias, stiffness and amplifier are rough guesses (the
    slow sweeps cannot inform them), and the friction values are starting
    points for the fit.
    """
    sources = {
        "transmission.n": "ORIGIN.md: ZXF17 strain-wave gear, ratio 50:1",
        "motor.torque_constant": "median torque_Nm / iq_A of the sweep file, / 50 (motor side)",
        "motor.inertia": "guess (frameless motor rotor + wave generator); fitted",
        "load.inertia": "guess (output flange + 100 g arm); fitted",
        "compliance.stiffness": "guess for a size-17 strain-wave gear; not identifiable here",
        "friction.output.coulomb": "starting value for the fit",
        "friction.output.viscous": "starting value for the fit",
        "amplifier.current_limit": "the owner's torque cap 18 N m / torque constant",
        "sensors": "ORIGIN.md: 14-bit absolute encoders on rotor and output",
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
