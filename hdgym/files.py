"""Writing output files: atomically, with the usual permissions, never into results/ by accident.

- :func:`atomic_write_text` / :func:`atomic_write_bytes` / :func:`atomic_path`
  write through a temporary file beside the target and a rename, so an
  interrupted run (a crash, Ctrl-C) never leaves a half-written file. The
  finished file gets the mode a plain ``open()`` would give it (0666 less the
  umask), not the temporary file's private 0600.
- :func:`check_out` is the results/ policy: the committed pages in
  ``results/`` are written only when asked for by name (``--out results/...``
  or ``hdgym results``), and a ``--quick`` run never writes there.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["atomic_path", "atomic_write_bytes", "atomic_write_text", "check_out",
           "in_results", "umask_mode"]


def umask_mode(directory: bool = False) -> int:
    """The mode ``open()`` (0o666) or ``mkdir()`` (0o777) gives under the current umask."""
    mask = os.umask(0)
    os.umask(mask)
    return (0o777 if directory else 0o666) & ~mask


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success rename it onto ``path``.

    For writers that want a file name (``savefig``, ``np.savez``): write to
    the yielded path; if the block raises (or is interrupted) the temporary
    file is removed and ``path`` is left as it was.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=path.suffix)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, umask_mode())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file and a rename."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` through a temporary file and a rename."""
    atomic_write_bytes(path, text.encode())


def in_results(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` lies in a project's ``results/`` folder (one beside a pyproject.toml)."""
    p = Path(path).resolve()
    return any(a.name == "results" and (a.parent / "pyproject.toml").is_file()
               for a in (p, *p.parents))


def check_out(path: str | os.PathLike[str], quick: bool, flag: str = "--out") -> None:
    """Refuse a quick run's output inside results/ (the committed pages).

    Raises:
        ValueError: ``quick`` and ``path`` in results/ (the message names ``flag``).
    """
    if quick and in_results(path):
        raise ValueError(f"{flag} {path}: quick runs never write into results/ (the committed "
                         "pages); give another folder, e.g. runs/")
