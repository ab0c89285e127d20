"""Record: the measured or simulated time series of one run, with CSV in/out.

Long because: the CSV reader's checks (one clear error per bad file, row and column)
sit beside the format they check, so the whole contract of a record reads in one place.

A record is a CSV file: optional leading metadata lines ``# key: value``, one
header row naming the columns, then one row per sample at a uniform ``time``
step. Everything is SI (s, rad, rad/s, A, N m)::

    # ratio: 161.0
    # configuration: flexspline
    # locked_output: false
    time,current_command,motor_angle,output_angle
    0.0,0.0,0.0,0.0
    0.001,0.5,1.2e-05,7.5e-08

Known columns: ``time``, ``current_command``,
``motor_current``, ``motor_angle``, ``output_angle``, ``motor_velocity``,
``output_torque``, ``load_torque``. ``time`` and ``motor_angle`` are always
required; ``output_angle`` is required unless ``locked_output`` is true. Other
columns (``output_velocity``, ``reference``, ...) are kept, and must be numeric
too. Columns are matched by name, so their order in the file does not matter.

Known metadata keys and their checks: ``ratio`` (a number > 1),
``configuration`` (the grounded port: ``flexspline`` or ``circular_spline``),
``locked_output`` (``true``/``false``), ``units`` (must be ``SI``), ``preset``
and ``source`` (free text). Other keys are kept as text.

Every problem with a file raises one :class:`RecordError` (a ``ValueError``)
whose message names the file, the row (the 1-based line number in the file,
counting metadata and header lines) and the column, e.g.
``run.csv: row 17, column 'motor_angle': 'abc' is not a number``. Records
built in memory are validated the same way; their messages name the sample
index instead of a file row.

Missing optional columns: the column properties (``current_command``,
``output_torque``, ...) return ``None``; :meth:`Record.column` raises
:class:`RecordError` naming the columns the record has.
"""

from __future__ import annotations

import difflib
import math
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hdgym.files import atomic_write_text
from hdgym.params import GROUNDED

__all__ = [
    "DT_RTOL",
    "KNOWN_COLUMNS",
    "META_KEYS",
    "REQUIRED_COLUMNS",
    "Record",
    "RecordError",
    "read_record",
]

KNOWN_COLUMNS: tuple[str, ...] = (
    "time",
    "current_command",
    "motor_current",
    "motor_angle",
    "output_angle",
    "motor_velocity",
    "output_torque",
    "load_torque",
)
REQUIRED_COLUMNS: tuple[str, ...] = ("time", "motor_angle")
META_KEYS: tuple[str, ...] = ("ratio", "configuration", "locked_output", "preset", "source",
                              "units", "kind")
#: ``# kind: command`` marks a command file (an experiment protocol to run on a
#: rig or the simulator): it needs only ``time`` and ``current_command``.
COMMAND_COLUMNS: tuple[str, ...] = ("time", "current_command")
DT_RTOL = 0.01
"""Allowed deviation of any time step from the median step, relative to it."""

_UNITS = "time s, angles rad, velocities rad/s, currents A, torques N m"
_KEY_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-]*\Z")
_TRUE = ("true",)
_FALSE = ("false",)


class RecordError(ValueError):
    """A record file or in-memory record is invalid; the message says where."""


# ------------------------------------------------------------------ helpers


def _rowname(row: int, first_line: int | None) -> str:
    """``row N`` (1-based file line) when reading a file, else ``sample i`` (0-based index)."""
    return f"row {first_line + row}" if first_line is not None else f"sample {row}"


def _where(source: str, row: int | None = None, column: str | None = None,
           first_line: int | None = None) -> str:
    """``source: row N, column 'c'`` (file rows) or ``source: sample i, ...``."""
    parts = []
    if row is not None:
        parts.append(_rowname(row, first_line))
    if column is not None:
        parts.append(f"column {column!r}")
    return f"{source}: " + ", ".join(parts) if parts else f"{source}"


def _expected_names_hint(have: list[str], missing: str) -> str:
    # a known column is itself, never a misspelling of another (motor_angle is no output_angle)
    unknown = [h for h in have if h not in KNOWN_COLUMNS]
    close = difflib.get_close_matches(missing, unknown, n=1, cutoff=0.6)
    if not close:
        close = [h for h in unknown if h.lower().startswith(missing) or missing in h.lower()][:1]
    hint = (f"expected column names ({_UNITS}): {', '.join(KNOWN_COLUMNS)}")
    if close:
        hint = (f"{close[0]!r} is not {missing!r}: rename the column to exactly {missing!r} "
                f"(and convert it to SI units); " + hint)
    return hint


def _parse_float(text: str) -> float:
    """``float(text)``, except that underscores and non-ASCII digits are refused."""
    if "_" in text or not text.isascii():
        raise ValueError(text)
    return float(text)


def _check_meta(key: str, value: str, where: str) -> None:
    """Raise :class:`RecordError` if a known metadata key has a bad value."""
    if not _KEY_RE.match(key):
        raise RecordError(f"{where}: metadata key {key!r} is malformed; keys are words such as "
                          f"{', '.join(META_KEYS)}")
    if "\n" in value or "\r" in value:
        raise RecordError(f"{where}: metadata {key!r} must be one line, got {value!r}")
    if key == "ratio":
        try:
            ratio = _parse_float(value)
        except ValueError:
            ratio = math.nan
        if not (math.isfinite(ratio) and ratio > 1):
            raise RecordError(f"{where}: metadata 'ratio' must be a number > 1 (motor angle per "
                              f"output angle), got {value!r}")
    elif key == "locked_output":
        if value.lower() not in _TRUE + _FALSE:
            raise RecordError(f"{where}: metadata 'locked_output' must be true or false, "
                              f"got {value!r}")
    elif key == "configuration":
        if value not in GROUNDED:
            raise RecordError(f"{where}: metadata 'configuration' must name the grounded port, "
                              f"one of {', '.join(GROUNDED)}; got {value!r}")
    elif key == "kind":
        if value not in ("record", "command"):
            raise RecordError(f"{where}: metadata 'kind' must be record or command, "
                              f"got {value!r}")
    elif key == "units":
        if value.upper() != "SI":
            raise RecordError(f"{where}: metadata 'units' must be SI ({_UNITS}), got {value!r}; "
                              f"convert the data to SI")


def _meta_text(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    return str(value).strip()


def _is_locked(meta: Mapping[str, str]) -> bool:
    return meta.get("locked_output", "false").strip().lower() in _TRUE


def _check_column_name(name: Any, source: str) -> str:
    if not isinstance(name, str):
        raise RecordError(f"{source}: column names must be strings, got {name!r}")
    bad = (not name or name != name.strip() or name.startswith("#")
           or any(c in name for c in ',"\n\r'))
    if bad:
        raise RecordError(f"{source}: column name {name!r} cannot be written to CSV (empty, "
                          f"padded with spaces, starting with '#' or containing a comma, quote "
                          f"or line break)")
    return name


def _required(meta: Mapping[str, str]) -> tuple[str, ...]:
    if meta.get("kind", "record").strip() == "command":
        return COMMAND_COLUMNS
    return REQUIRED_COLUMNS if _is_locked(meta) else REQUIRED_COLUMNS + ("output_angle",)


# ------------------------------------------------------------------ the record


@dataclass(frozen=True, eq=False)
class Record:
    """One run as columns of equal length, plus metadata.

    Attributes:
        columns: column name -> float64 array (read-only), all the same
            length, in file order.
        meta: metadata ``key -> value`` text (the ``# key: value`` lines).
        source: where the record came from (a file path, or ``"record"``);
            used in error messages.

    Construction validates (see :meth:`validate`) and copies the arrays.
    """

    columns: dict[str, np.ndarray]
    meta: dict[str, str] = field(default_factory=dict)
    source: str = "record"

    def __post_init__(self) -> None:
        columns, meta = Record.validate(self.columns, self.meta, source=self.source)
        object.__setattr__(self, "columns", columns)
        object.__setattr__(self, "meta", meta)

    # -- validation

    @staticmethod
    def validate(columns: Mapping[str, Any], meta: Mapping[str, Any] | None = None, *,
                 source: str = "record", first_line: int | None = None,
                 ) -> tuple[dict[str, np.ndarray], dict[str, str]]:
        """Check a record and return its normalized ``(columns, meta)``.

        Args:
            columns: name -> 1-D numeric sequence, all of one length.
            meta: metadata; values are turned into text (``True`` -> ``"true"``).
            source: name used at the start of every message (e.g. the file).
            first_line: file line number of the first sample; when given,
                messages name ``row <line>`` rather than ``sample <index>``.

        Returns:
            Fresh read-only float64 arrays in the given order, and the metadata
            as ``dict[str, str]``.

        Raises:
            RecordError: naming the source, row/sample and column of the first
                problem: bad metadata, a missing required column, a non-numeric
                or non-finite value, unequal lengths, fewer than two samples,
                time not strictly increasing or its step not uniform (beyond
                ``DT_RTOL`` of the median step).
        """
        meta_out: dict[str, str] = {}
        if meta is None:
            meta = {}
        if not isinstance(meta, Mapping):
            raise RecordError(f"{source}: meta must be a mapping, got {type(meta).__name__}")
        for key, value in meta.items():
            key = str(key).strip()
            text = _meta_text(value)
            _check_meta(key, text, source)
            meta_out[key] = text

        if not isinstance(columns, Mapping):
            raise RecordError(f"{source}: columns must be a mapping name -> array, "
                              f"got {type(columns).__name__}")
        out: dict[str, np.ndarray] = {}
        length = None
        for name, values in columns.items():
            _check_column_name(name, source)
            try:
                if np.iscomplexobj(values):
                    raise TypeError("complex")
                arr = np.array(values, dtype=np.float64)
            except (TypeError, ValueError, OverflowError):
                raise RecordError(f"{_where(source, None, name)}: values are not numeric "
                                  f"(real numbers expected)") from None
            if arr.ndim != 1:
                raise RecordError(f"{_where(source, None, name)}: must be one-dimensional, "
                                  f"got shape {arr.shape}")
            if length is None:
                length = arr.shape[0]
            elif arr.shape[0] != length:
                first = next(iter(out))
                raise RecordError(f"{_where(source, None, name)}: has {arr.shape[0]} samples "
                                  f"but column {first!r} has {length}")
            arr.setflags(write=False)
            out[name] = arr

        have = list(out)
        for name in _required(meta_out):
            if name not in out:
                why = "" if name != "output_angle" else " (or set metadata locked_output: true)"
                raise RecordError(f"{source}: missing required column {name!r}{why}; the record "
                                  f"has columns {', '.join(have) or '(none)'}; "
                                  f"{_expected_names_hint(have, name)}")

        n = length or 0
        if n < 2:
            raise RecordError(f"{source}: {n} data row(s); a record needs at least 2 samples "
                              f"(to define the time step)")

        # first non-finite value in file order (row-major)
        bad_row, bad_col = None, None
        for name, arr in out.items():
            finite = np.isfinite(arr)
            if not finite.all():
                i = int(np.argmin(finite))
                if bad_row is None or i < bad_row:
                    bad_row, bad_col = i, name
        if bad_row is not None:
            value = float(out[bad_col][bad_row])
            raise RecordError(f"{_where(source, bad_row, bad_col, first_line)}: {value!r} is not "
                              f"finite; records must not contain NaN or inf")

        t = out["time"]
        step = np.diff(t)
        if not (step > 0).all():
            i = int(np.argmin(step > 0)) + 1
            now, before = float(t[i]), float(t[i - 1])
            what = "repeats" if now == before else "goes backwards from"
            prev = _rowname(i - 1, first_line)
            raise RecordError(f"{_where(source, i, 'time', first_line)}: time {now!r} {what} "
                              f"{before!r} ({prev}); time must be strictly increasing")
        median = float(np.median(step))
        off = np.abs(step - median) > DT_RTOL * median
        if off.any():
            i = int(np.argmax(off)) + 1
            raise RecordError(f"{_where(source, i, 'time', first_line)}: time step "
                              f"{float(step[i - 1])!r} s differs from the median step "
                              f"{median!r} s by more than {DT_RTOL:.0%}; the time step must be "
                              f"uniform (missing, repeated or resampled rows?)")
        return out, meta_out

    # -- access

    def __len__(self) -> int:
        return int(self.columns["time"].shape[0])

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Record):
            return NotImplemented
        return (self.meta == other.meta and set(self.columns) == set(other.columns)
                and all(np.array_equal(v, other.columns[k]) for k, v in self.columns.items()))

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        return (f"Record(source={self.source!r}, n={len(self)}, dt={self.dt!r}, "
                f"columns={list(self.columns)}, meta={self.meta!r})")

    @property
    def names(self) -> tuple[str, ...]:
        """Column names in file order."""
        return tuple(self.columns)

    def has(self, name: str) -> bool:
        """Whether the record has column ``name``."""
        return name in self.columns

    def column(self, name: str) -> np.ndarray:
        """Column ``name``; :class:`RecordError` listing the columns if absent."""
        try:
            return self.columns[name]
        except KeyError:
            raise RecordError(f"{self.source}: no column {name!r}; the record has "
                              f"{', '.join(self.columns)}") from None

    def _opt(self, name: str) -> np.ndarray | None:
        return self.columns.get(name)

    @property
    def time(self) -> np.ndarray:
        """s, strictly increasing, uniform step."""
        return self.columns["time"]

    @property
    def motor_angle(self) -> np.ndarray:
        """rad, input (WG) encoder (a command file has none: RecordError)."""
        return self.column("motor_angle")

    @property
    def output_angle(self) -> np.ndarray | None:
        """rad, output encoder (None only for locked-output records without it)."""
        return self._opt("output_angle")

    @property
    def current_command(self) -> np.ndarray | None:
        """A, amplifier input, or None."""
        return self._opt("current_command")

    @property
    def motor_current(self) -> np.ndarray | None:
        """A, measured, or None."""
        return self._opt("motor_current")

    @property
    def motor_velocity(self) -> np.ndarray | None:
        """rad/s, tachometer, or None."""
        return self._opt("motor_velocity")

    @property
    def output_torque(self) -> np.ndarray | None:
        """N m, flexspline torque sensor, or None."""
        return self._opt("output_torque")

    @property
    def load_torque(self) -> np.ndarray | None:
        """N m, external load applied, or None."""
        return self._opt("load_torque")

    @property
    def dt(self) -> float:
        """Sample period, s: ``(time[-1] - time[0]) / (len - 1)``."""
        t = self.columns["time"]
        return float((t[-1] - t[0]) / (t.shape[0] - 1))

    @property
    def duration(self) -> float:
        """``time[-1] - time[0]``, s."""
        t = self.columns["time"]
        return float(t[-1] - t[0])

    @property
    def locked_output(self) -> bool:
        """Metadata ``locked_output`` (False when absent)."""
        return _is_locked(self.meta)

    @property
    def ratio(self) -> float | None:
        """Metadata ``ratio`` as a number, or None when absent."""
        return float(self.meta["ratio"]) if "ratio" in self.meta else None

    def slice(self, t0: float | None = None, t1: float | None = None) -> Record:
        """Samples with ``t0 <= time < t1`` (either end may be None), as a Record.

        Times are kept as they are (not shifted to start at 0). Raises
        :class:`RecordError` if fewer than two samples remain.
        """
        t = self.columns["time"]
        keep = np.ones(t.shape, dtype=bool)
        if t0 is not None:
            keep &= t >= t0
        if t1 is not None:
            keep &= t < t1
        n = int(keep.sum())
        if n < 2:
            raise RecordError(f"{self.source}: slice({t0!r}, {t1!r}) keeps {n} sample(s); a "
                              f"record needs at least 2 (time runs {float(t[0])!r} to "
                              f"{float(t[-1])!r} s)")
        return Record({k: v[keep] for k, v in self.columns.items()}, dict(self.meta),
                      self.source)

    # -- CSV

    def to_text(self) -> str:
        """The CSV text: metadata lines, header row, rows in full precision (repr)."""
        columns, meta = Record.validate(self.columns, self.meta, source=self.source)
        lines = [f"# {k}: {v}" for k, v in meta.items()]
        lines.append(",".join(columns))
        table = np.column_stack(list(columns.values())).tolist()
        # repr of a list of floats formats every float with repr (shortest round trip)
        body = repr(table)[2:-2].replace("], [", "\n").replace(", ", ",")
        return "\n".join(lines) + "\n" + body + "\n"

    def to_csv(self, path: str | os.PathLike[str]) -> None:
        """Write the record to ``path`` atomically (temporary file + rename).

        The record is validated first; nothing is written if it is invalid
        (:class:`RecordError`) or if the write fails (:class:`RecordError`
        naming the path; no partial file is left behind).
        """
        text = self.to_text()
        try:
            atomic_write_text(path, text)
        except (OSError, UnicodeError) as exc:
            reason = getattr(exc, "strerror", None) or exc
            raise RecordError(f"{path}: cannot write: {reason}") from exc

    @classmethod
    def from_text(cls, text: str, source: str = "<text>", kind: str | None = None) -> Record:
        """Parse CSV ``text`` (see the module docstring); ``source`` names it in errors.

        ``kind`` is the ``# kind:`` of a file that does not say (``"command"``:
        only ``time`` and ``current_command`` are required).
        """
        columns, meta, first_line = _parse(text, source, kind)
        columns, meta = Record.validate(columns, meta, source=source, first_line=first_line)
        rec = object.__new__(cls)
        object.__setattr__(rec, "columns", columns)
        object.__setattr__(rec, "meta", meta)
        object.__setattr__(rec, "source", source)
        return rec

    @classmethod
    def from_csv(cls, path: str | os.PathLike[str], kind: str | None = None) -> Record:
        """Read and validate a record file; :class:`RecordError` on any problem.

        ``kind``: as in :meth:`from_text`.
        """
        source = str(path)
        try:
            raw = Path(path).read_bytes()
        except FileNotFoundError:
            raise RecordError(f"{source}: cannot read: no such file") from None
        except IsADirectoryError:
            raise RecordError(f"{source}: cannot read: is a directory") from None
        except OSError as exc:
            raise RecordError(f"{source}: cannot read: {exc.strerror or exc}") from None
        try:
            text = raw.decode("utf-8-sig")
        except UnicodeDecodeError as exc:
            row = raw.count(b"\n", 0, exc.start) + 1
            raise RecordError(f"{source}: row {row}: not UTF-8 text (byte "
                              f"{raw[exc.start:exc.start + 1]!r} at offset {exc.start})") from None
        return cls.from_text(text, source, kind)


def read_record(path: str | os.PathLike[str], kind: str | None = None) -> Record:
    """Read and validate a record file (same as :meth:`Record.from_csv`)."""
    return Record.from_csv(path, kind)


# ------------------------------------------------------------------ parsing


def _parse(text: str, source: str, kind: str | None = None
           ) -> tuple[dict[str, np.ndarray], dict[str, str], int]:
    """Split CSV text into columns; return them, the metadata and the first data line.

    ``kind``: the ``# kind:`` of a file that does not say.
    """
    if "\r" in text:
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    if text.startswith("\ufeff"):
        text = text[1:]
    if not text.strip():
        raise RecordError(f"{source}: file is empty")

    # metadata and blank lines, then the header
    meta: dict[str, str] = {}
    pos, line_no = 0, 0
    header_line = None
    while pos < len(text):
        end = text.find("\n", pos)
        end = len(text) if end < 0 else end
        line = text[pos:end]
        line_no += 1
        pos = end + 1
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("#"):
            body = stripped[1:].strip()
            key, colon, value = body.partition(":")
            key, value = key.strip(), value.strip()
            where = f"{source}: row {line_no}"
            if not colon or not key:
                raise RecordError(f"{where}: malformed metadata line {line!r}; metadata lines "
                                  f"read '# key: value'")
            if not _KEY_RE.match(key):
                raise RecordError(f"{where}: malformed metadata line {line!r}: key {key!r} is "
                                  f"not a single word; metadata lines read '# key: value'")
            if key in meta:
                raise RecordError(f"{where}: metadata key {key!r} appears twice")
            _check_meta(key, value, where)
            meta[key] = value
            continue
        header_line = line_no
        break
    if kind is not None:
        meta.setdefault("kind", kind)
    if header_line is None:
        raise RecordError(f"{source}: no header row (only metadata lines); the first line "
                          f"after the '# key: value' lines must name the columns, e.g. "
                          f"time,current_command,motor_angle,output_angle")

    names = [n.strip() for n in line.split(",")]
    names = [n[1:-1].strip() if len(n) >= 2 and n[0] == n[-1] == '"' else n for n in names]
    hwhere = f"{source}: row {header_line} (header)"
    try:
        [_parse_float(n) for n in names]
    except ValueError:
        pass
    else:
        raise RecordError(f"{hwhere}: no header row: the line looks like data; the first line "
                          f"after the '# key: value' lines must name the columns, e.g. "
                          f"time,current_command,motor_angle,output_angle")
    for k, name in enumerate(names):
        if not name:
            raise RecordError(f"{hwhere}: column {k + 1} has an empty name")
        if name in names[:k]:
            raise RecordError(f"{hwhere}, column {name!r}: duplicate column name")
    for name in _required(meta):
        if name not in names:
            why = "" if name != "output_angle" else " (or add '# locked_output: true')"
            raise RecordError(f"{hwhere}: missing required column {name!r}{why}; the file has "
                              f"columns {', '.join(names)}; {_expected_names_hint(names, name)}")

    ncol = len(names)
    first_line = header_line + 1
    data = text[pos:].rstrip()
    if not data:
        raise RecordError(f"{source}: 0 data rows after the header (row {header_line}); a "
                          f"record needs at least 2 samples")
    lines = data.split("\n")
    fast = (data.isascii() and "_" not in data
            and all(c == ncol - 1 for c in map(str.count, lines, [","] * len(lines))))
    table = None
    if fast:
        try:
            table = np.array(data.replace("\n", ",").split(","), dtype=np.float64)
        except (ValueError, TypeError, OverflowError):
            table = None
    if table is None:
        table = _scan(lines, names, source, first_line)
    table = table.reshape(len(lines), ncol)

    finite = np.isfinite(table)
    if not finite.all():
        flat = int(np.argmin(finite.ravel()))
        i, j = divmod(flat, ncol)
        field_text = lines[i].split(",")[j].strip()
        raise RecordError(f"{source}: row {first_line + i}, column {names[j]!r}: {field_text!r} "
                          f"is not finite; records must not contain NaN or inf")
    columns = {name: np.ascontiguousarray(table[:, j]) for j, name in enumerate(names)}
    return columns, meta, first_line


def _scan(lines: list[str], names: list[str], source: str, first_line: int) -> np.ndarray:
    """Parse in blocks; a block that fails the fast path is scanned row by row to name the
    first bad row. Returns the flat values if everything parses."""
    ncol = len(names)
    out = np.empty(len(lines) * ncol, dtype=np.float64)
    block = 4096
    for start in range(0, len(lines), block):
        chunk = lines[start:start + block]
        text = ",".join(chunk)
        if (text.isascii() and "_" not in text and "#" not in text
                and all(line.count(",") == ncol - 1 and line.strip() for line in chunk)):
            try:
                out[start * ncol:(start + len(chunk)) * ncol] = np.array(text.split(","),
                                                                         dtype=np.float64)
                continue
            except (ValueError, TypeError, OverflowError):
                pass
        _scan_rows(chunk, names, source, first_line + start, out[start * ncol:])
    return out


def _scan_rows(lines: list[str], names: list[str], source: str, first_line: int,
               out: np.ndarray) -> None:
    """Parse rows one field at a time into ``out``; raise on the first bad row."""
    ncol = len(names)
    for i, line in enumerate(lines):
        row = first_line + i
        if not line.strip():
            raise RecordError(f"{source}: row {row}: empty line inside the data; remove it")
        if line.lstrip().startswith("#"):
            raise RecordError(f"{source}: row {row}: '#' line after the header; metadata lines "
                              f"must come before the header row")
        fields = line.split(",")
        if len(fields) < ncol:
            raise RecordError(f"{source}: row {row}, column {names[len(fields)]!r}: missing "
                              f"value; the row has {len(fields)} fields but the header has "
                              f"{ncol} (truncated row?)")
        if len(fields) > ncol:
            raise RecordError(f"{source}: row {row}: {len(fields)} fields but the header has "
                              f"{ncol} (extra value {fields[ncol].strip()!r} after column "
                              f"{names[-1]!r})")
        for j, f in enumerate(fields):
            try:
                out[i * ncol + j] = _parse_float(f)
            except ValueError:
                what = "empty field" if not f.strip() else f"{f.strip()!r}"
                raise RecordError(f"{source}: row {row}, column {names[j]!r}: {what} is not a "
                                  f"number") from None
