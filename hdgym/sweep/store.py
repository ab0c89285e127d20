"""``results.csv``: one whole row per finished job, appended with flush + fsync.

A kill can leave at most a truncated last line (no newline); opening the
store drops it, so a resumed sweep starts from whole rows. Every value sits
on one physical line (newlines in text are replaced), so "a line" and "a
row" are the same thing.

The header is the union of the columns seen so far: when a job returns a
metric no earlier row had, the file is rewritten (atomically) with the wider
header and the old rows get empty cells there.
"""

from __future__ import annotations

import csv
import io
import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from hdgym.files import atomic_write_text

__all__ = ["ResultsStore", "format_value", "read_rows"]


def format_value(v: Any) -> str:
    """One CSV cell: floats round-trip (``repr``), None empty, text on one line."""
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else str(v)
    if isinstance(v, int):
        return str(v)
    return str(v).replace("\r", " ").replace("\n", " ")


def _line(values: Sequence[str]) -> str:
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(values)
    return buf.getvalue()


def read_rows(path: str | os.PathLike[str]) -> tuple[list[str], list[dict[str, str]]]:
    """Header and rows of a results CSV (a truncated last line is ignored)."""
    text = Path(path).read_text()
    if text and not text.endswith("\n"):
        text = text[: text.rfind("\n") + 1]
    reader = csv.reader(io.StringIO(text))
    header = next(reader, None)
    if header is None:
        return [], []
    rows = [dict(zip(header, r, strict=True)) for r in reader if len(r) == len(header)]
    return header, rows


class ResultsStore:
    """Append-only results CSV with crash-safe rows.

    Args:
        path: the CSV file (created with ``columns`` if missing).
        columns: the columns every row has, in order (more are added as met).
        key: the column that identifies a job (``job_id``).
    """

    def __init__(self, path: str | os.PathLike[str], columns: Sequence[str], key: str = "job_id"):
        self.path = Path(path)
        self.key = key
        self.dropped = 0  # truncated or malformed lines dropped on open
        self.header: list[str] = list(columns)
        self.done: set[str] = set()
        if self.path.exists() and self.path.stat().st_size > 0:
            self._open_existing(columns)
        else:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(self.path, _line(self.header))
        self._fh = open(self.path, "a", newline="")  # noqa: SIM115 - closed in close()

    def _open_existing(self, columns: Sequence[str]) -> None:
        raw = self.path.read_bytes()
        whole = raw if raw.endswith(b"\n") else raw[: raw.rfind(b"\n") + 1]
        if len(whole) != len(raw):
            self.dropped += 1
        text = whole.decode("utf-8", errors="replace")
        reader = csv.reader(io.StringIO(text))
        header = next(reader, None)
        if not header or self.key not in header:
            raise ValueError(f"{self.path}: not a sweep results file (no {self.key!r} column); "
                             f"move it away or pick another --out")
        rows = []
        for r in reader:
            if len(r) == len(header):
                rows.append(dict(zip(header, r, strict=True)))
            else:
                self.dropped += 1
        self.header = list(header) + [c for c in columns if c not in header]
        self.done = {r[self.key] for r in rows}
        if self.dropped or self.header != header:
            self._rewrite(rows)

    def set_aside(self, stale: Callable[[Mapping[str, str]], bool], dest: str | os.PathLike[str]
                  ) -> int:
        """Move the rows for which ``stale(row)`` is true to the CSV ``dest`` (appended,
        kept for reference), so they count neither as done nor in a summary; return how
        many moved."""
        _, rows = read_rows(self.path)
        old = [r for r in rows if stale(r)]
        if not old:
            return 0
        dest = Path(dest)
        kept_header, kept = read_rows(dest) if dest.is_file() else ([], [])
        header = kept_header + [c for c in self.header if c not in kept_header]
        parts = [_line(header)] + [_line([r.get(c, "") for c in header]) for r in kept + old]
        atomic_write_text(dest, "".join(parts))
        self._fh.close()
        self._rewrite(r for r in rows if not stale(r))
        self._fh = open(self.path, "a", newline="")  # noqa: SIM115 - closed in close()
        self.done = {r[self.key] for r in rows if not stale(r)}
        return len(old)

    def _rewrite(self, rows: Iterable[Mapping[str, str]]) -> None:
        parts = [_line(self.header)]
        parts += [_line([r.get(c, "") for c in self.header]) for r in rows]
        atomic_write_text(self.path, "".join(parts))

    def append(self, row: Mapping[str, Any]) -> None:
        """Write one row durably (flush + fsync); widen the header if needed."""
        new = [c for c in row if c not in self.header]
        if new:
            self._fh.close()
            _, rows = read_rows(self.path)
            self.header += new
            self._rewrite(rows)
            self._fh = open(self.path, "a", newline="")  # noqa: SIM115
        self._fh.write(_line([format_value(row.get(c)) for c in self.header]))
        self._fh.flush()
        os.fsync(self._fh.fileno())
        self.done.add(str(row[self.key]))

    def close(self) -> None:
        self._fh.close()

    def __enter__(self) -> ResultsStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
