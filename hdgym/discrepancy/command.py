"""``hdgym diagnose``: read the record(s), diagnose, write the report."""

from __future__ import annotations

import os
from pathlib import Path

from hdgym.params import JointParams
from hdgym.record import read_record

from .report import write_report
from .workflow import diagnose


def diagnose_files(record_path: str | os.PathLike[str], params: JointParams, out: Path,
                   validate: str | os.PathLike[str] | None = None, **kwargs) -> dict:
    """Read the record(s), diagnose, write ``out/report.json`` + ``report.md`` + figures.

    A bad record raises its :class:`hdgym.record.RecordError` unchanged, before
    anything is written (no report directory is left behind).

    Returns:
        the report.json content.
    """
    rec = read_record(record_path)
    val = read_record(validate) if validate is not None else None
    diag = diagnose(rec, params, val, **kwargs)
    return write_report(diag, Path(out))
