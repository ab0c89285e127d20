"""``run_sweep``: validate a spec, skip finished jobs, run the rest, summarize."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path

from hdgym.files import atomic_write_text, check_out
from hdgym.sweep.backends import BACKENDS, FIXED_COLUMNS, iter_results, param_columns
from hdgym.sweep.spec import SweepSpec, load_spec
from hdgym.sweep.store import ResultsStore

__all__ = ["SweepResult", "run_sweep"]

_BUNDLED = resources.files("hdgym.sweep.specs")
#: where rows computed on other physics (another :func:`~hdgym.sweep.job.physics_fingerprint`
#: of their preset) go when a sweep resumes
STALE_FILE = "results.stale.csv"


def _task_of(row: dict[str, str]) -> str:
    """The task digest a row was made for (:attr:`Job.task`, kept in its inputs; '' if none)."""
    try:
        return str(json.loads(row.get("inputs") or "{}").get("task", ""))
    except ValueError:
        return ""


@dataclass(frozen=True)
class SweepResult:
    """What a call to :func:`run_sweep` did."""

    out_dir: Path
    total: int  # jobs in the spec
    skipped: int  # already in results.csv (on the same physics)
    ran: int  # run now
    errors: int  # of those, with status "error"
    seconds: float
    summary: Path | None
    stale: int = 0  # rows made on other physics, moved to STALE_FILE


def _copy_spec(spec: SweepSpec, out_dir: Path) -> None:
    """``DIR/spec.toml``; a different earlier spec is kept as ``spec.N.toml``."""
    dest = out_dir / "spec.toml"
    if dest.exists():
        old = dest.read_text()
        if old == spec.text:
            return
        k = 1
        while (out_dir / f"spec.{k}.toml").exists():
            k += 1
        atomic_write_text(out_dir / f"spec.{k}.toml", old)
    atomic_write_text(dest, spec.text)


def run_sweep(spec_path: str | Path, out_dir: str | Path, backend: str = "local",
              address: str | None = None, workers: int | None = None, *,
              quick: bool | None = None, summarize: bool = True,
              progress: bool = True, summary_dir: str | Path | None = None) -> SweepResult:
    """Run the sweep ``spec_path`` into ``out_dir`` (resuming if it has results).

    Args:
        spec_path: the spec TOML (see :mod:`hdgym.sweep.spec`) or a bundled spec's name.
        out_dir: gets ``results.csv`` (one row per job), ``spec.toml`` and the
            summary (``summary.md``, ``summary.png``; also
            ``<summary_dir>/<name>.md/.png`` when the spec sets ``summary_dir``).
            Rows of the spec's presets made on other physics (code, sensors or
            preset numbers; the ``physics`` column), or for another task (the
            scenario's task code or config, :attr:`Job.task`), move to ``results.stale.csv``
            and their jobs run again.
        backend: ``"local"`` (process pool) or ``"ray"``.
        address: Ray cluster address (``None``: start Ray locally).
        workers: processes (local; default ``os.cpu_count()``) or CPUs for a
            local Ray; 1 runs jobs in this process.
        quick: override the spec's ``quick`` key (shorter runs).
        summarize: write the summary at the end.
        progress: show a progress bar and a closing line.
        summary_dir: also copy the summary to ``<summary_dir>/<name>.md/.png``
            (default: the spec's ``summary_dir``, if any).

    Raises:
        ValueError: a bad spec (naming file and line) or bad arguments, before
            any job runs.
    """
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; known: {', '.join(BACKENDS)}")
    if workers is not None and workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if address is not None and backend != "ray":
        raise ValueError("--address is for --backend ray")
    bundled = _BUNDLED.joinpath(f"{spec_path}.toml")
    if not Path(spec_path).is_file() and bundled.is_file():  # a bundled spec's name
        spec_file: str | Path = Path(str(bundled))
    else:
        spec_file = spec_path
    spec = load_spec(spec_file, quick=quick)
    check_out(out_dir, spec.quick)  # results/ policy: quick runs never write there
    if summary_dir is not None or spec.summary_dir is not None:
        check_out(summary_dir or spec.summary_dir, spec.quick, "summary_dir")
    jobs = spec.jobs()
    ids = [j.job_id for j in jobs]
    if len(set(ids)) != len(ids):  # pragma: no cover - the spec forbids duplicates
        raise ValueError(f"{spec.path}: two jobs have the same inputs")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    _copy_spec(spec, out_dir)
    jobs = [replace(j, workdir=str((out_dir / "jobs").resolve())) for j in jobs]

    columns = list(FIXED_COLUMNS) + (param_columns(jobs[0]) if jobs else [])
    t0 = time.perf_counter()
    ran = errors = 0
    # physics each preset runs on now, and the task each scenario runs (Job.task);
    # rows made on other physics or for another task are set aside
    physics: dict[str, set[str]] = {}
    tasks: dict[tuple[str, str], set[str]] = {}
    for j in jobs:
        physics.setdefault(j.preset, set()).add(j.physics)
        tasks.setdefault((j.preset, j.scenario), set()).add(j.task)

    def is_stale(r: dict[str, str]) -> bool:
        if r.get("preset") not in physics:
            return False
        if r.get("physics") not in physics[r["preset"]]:
            return True
        now = tasks.get((r["preset"], r.get("scenario", "")))
        return now is not None and _task_of(r) not in now

    with ResultsStore(out_dir / "results.csv", columns) as store:
        stale = store.set_aside(is_stale, out_dir / STALE_FILE)
        todo = [j for j in jobs if j.job_id not in store.done]
        skipped = len(jobs) - len(todo)
        bar = None
        if progress:
            from hdgym.progress import bar as progress_bar

            # left on screen at the end, above the closing line, as before
            bar = progress_bar(total=len(jobs), initial=skipped, desc=f"sweep {spec.name}",
                               unit="job", leave=True)
        try:
            for row in iter_results(todo, backend, address=address, workers=workers):
                store.append(row)
                ran += 1
                if row["status"] != "ok":
                    errors += 1
                if bar is not None:
                    bar.update(1)
                    if errors:
                        bar.set_postfix(errors=errors)
        finally:
            if bar is not None:
                bar.close()
    seconds = time.perf_counter() - t0
    summary = None
    if summarize:
        from hdgym.sweep.summary import summarize as _summarize

        command = f"hdgym sweep {spec_path} --out {out_dir}"
        if summary_dir is not None:
            command += f" --summary-dir {summary_dir}"
        if quick:
            command += " --quick"
        elif quick is not None:  # the CLI has no flag for quick=False: say it in Python
            command = (f"python -c \"from hdgym.sweep import run_sweep; "
                       f"run_sweep('{spec_path}', '{out_dir}', quick=False)\"")
        summary = _summarize(out_dir, command=command, dest=summary_dir)
    if progress:
        if stale:
            print(f"sweep {spec.name}: {stale} rows made on other physics moved to "
                  f"{out_dir / STALE_FILE}")
        print(f"sweep {spec.name}: {len(jobs)} jobs, {skipped} already done, {ran} run "
              f"({errors} errors) in {seconds:.1f} s on {backend}; "
              f"wrote {out_dir / 'results.csv'}" + (f", {summary}" if summary else ""))
    return SweepResult(out_dir, len(jobs), skipped, ran, errors, seconds, summary, stale)
