"""Current-command signals: ``step:3.2``, ``ramp:0:5``, ``sine:1:5``, ``chirp:1:1:100``,
``random:1:50`` or a CSV with ``time`` and ``current_command`` columns.

All amplitudes are in A and frequencies in Hz; signals are sampled at the
control period (held constant across it, as a DAC does).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy import signal as sps

KINDS = {"step": 1, "ramp": 2, "sine": 2, "chirp": 3, "random": 2}


def _numbers(spec: str, kind: str, parts: list[str]) -> list[float]:
    want = KINDS[kind]
    if len(parts) != want:
        raise ValueError(f"command {spec!r}: {kind} takes {want} number(s) separated by ':'")
    out = []
    for part in parts:
        try:
            v = float(part)
        except ValueError:
            raise ValueError(f"command {spec!r}: {part!r} is not a number") from None
        if not math.isfinite(v):
            raise ValueError(f"command {spec!r}: {part!r} is not finite")
        out.append(v)
    return out


def command_signal(spec: str | np.ndarray, time: np.ndarray,
                   rng: np.random.Generator | None = None) -> np.ndarray:
    """Sample the command ``spec`` at ``time`` (s, uniform from 0); returns A.

    Args:
        spec: a ``kind:args`` string, a path to a CSV with ``time`` and
            ``current_command``, or an array of currents (one per sample).
        time: sample times, s.
        rng: seeded generator for ``random`` (default: seed 0).

    Raises:
        ValueError: naming the command and what is wrong (unknown kind, wrong
            count of numbers, NaN, a CSV without the columns, wrong length).
    """
    time = np.asarray(time, dtype=float)
    if not isinstance(spec, str):
        arr = np.asarray(spec, dtype=float)
        if arr.shape != time.shape:
            raise ValueError(f"command: array has {arr.shape} samples, expected {time.shape}")
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            raise ValueError(
                f"command: sample {bad[0]} is {arr[bad[0]]!r}; commands must be finite")
        return arr.copy()
    kind, _, rest = spec.partition(":")
    if kind not in KINDS:
        if Path(spec).suffix.lower() == ".csv":
            return _from_csv(spec, time)
        raise ValueError(f"command {spec!r}: unknown kind {kind!r}; use one of "
                         f"{', '.join(KINDS)} or a CSV file")
    args = _numbers(spec, kind, rest.split(":") if rest else [])
    duration = float(time[-1] - time[0]) if time.size > 1 else 1.0
    if kind == "step":
        return np.full(time.shape, args[0])
    if kind == "ramp":
        return args[0] + (args[1] - args[0]) * (time - time[0]) / duration
    if kind == "sine":
        if args[1] < 0:
            raise ValueError(f"command {spec!r}: frequency must be >= 0 Hz")
        return args[0] * np.sin(2 * np.pi * args[1] * time)
    if kind == "chirp":
        if min(args[1], args[2]) < 0:
            raise ValueError(f"command {spec!r}: frequencies must be >= 0 Hz")
        return args[0] * sps.chirp(time, f0=args[1], t1=time[-1], f1=args[2], phi=-90)
    # random: Gaussian noise low-passed at the cutoff, scaled to RMS = amplitude
    amp, cutoff = args
    dt = float(time[1] - time[0]) if time.size > 1 else 1.0
    nyq = 0.5 / dt
    if not 0 < cutoff < nyq:
        raise ValueError(f"command {spec!r}: cutoff must be in (0, {nyq:g}) Hz (Nyquist)")
    rng = np.random.default_rng(0) if rng is None else rng
    white = rng.standard_normal(time.size + 200)
    sos = sps.butter(4, cutoff / nyq, output="sos")
    out = sps.sosfiltfilt(sos, white)[100:-100]
    return amp * out / max(float(np.std(out)), 1e-300)


def _from_csv(path: str, time: np.ndarray) -> np.ndarray:
    from hdgym.record import read_record

    rec = read_record(path, kind="command")  # two columns are enough: time,current_command
    if not rec.has("current_command"):
        raise ValueError(f"{path}: no column 'current_command'")
    return np.interp(time, rec.time - rec.time[0], rec.current_command)
