"""Where jobs run: a local process pool (default) or Ray tasks.

Both backends run :func:`run_job` on each :class:`~hdgym.sweep.job.Job`
and yield result rows as jobs finish (in completion order), keeping a
bounded number of jobs in flight so an interrupted sweep loses little and
memory stays flat for large sweeps.

Ray is optional (``pip install "hdgym[ray]"``). ``address=None`` starts a
local Ray instance (``ray.init()``); ``address="ray://head:10001"`` or
``"auto"`` joins an existing cluster, whose nodes need hdgym installed (the
drive of a preset *file* travels inside the job, bundled presets are read
on the node).
"""

from __future__ import annotations

import json
import multiprocessing as mp
import os
import time
from collections.abc import Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from importlib import metadata
from typing import Any

from hdgym.sweep.job import Job, draw_params

__all__ = ["BACKENDS", "FIXED_COLUMNS", "iter_results", "run_job"]

BACKENDS = ("local", "ray")

#: columns every row has, in this order; then ``param:``/``scale:`` columns, then metrics
FIXED_COLUMNS = ("job_id", "status", "preset", "scenario", "controller", "seed", "quick",
                 "physics", "hdgym_version", "elapsed_s", "error", "inputs")


def _version() -> str:
    try:
        return metadata.version("hdgym")
    except metadata.PackageNotFoundError:  # pragma: no cover - not installed
        return "unknown"


def param_columns(job: Job) -> list[str]:
    """The input columns a job's row carries: drawn values of grid and spread paths."""
    return [f"param:{p}" for p in sorted(set(job.grid) | set(job.spreads))]


def run_job(job: Job) -> dict[str, Any]:
    """Run one job; return its row (never raises for a failing job: status ``error``)."""
    from hdgym.sweep.scenarios import get_scenario

    t0 = time.perf_counter()
    inputs = job.inputs()
    row: dict[str, Any] = {
        "job_id": job.job_id, "status": "ok", "preset": job.preset, "scenario": job.scenario,
        "controller": job.label, "seed": job.seed, "quick": job.quick,
        "physics": inputs["physics"], "hdgym_version": _version(), "elapsed_s": None, "error": "",
        "inputs": json.dumps(inputs, sort_keys=True, separators=(",", ":")),
    }
    try:
        params, drawn = draw_params(job.base_params(), job.grid, job.spreads, job.drive_rng())
        for path, v in drawn.items():
            row[f"param:{path}"] = v if isinstance(v, (int, float, str)) else json.dumps(v)
        metrics = get_scenario(job.scenario).fn(params, job)
        for k, v in dict(metrics).items():
            if k in row:
                raise ValueError(f"scenario {job.scenario!r} returned metric {k!r}, "
                                 f"which is a reserved column name")
            row[k] = float(v)
    except Exception as exc:  # noqa: BLE001 - a failing job is a result, not a crash
        row["status"] = "error"
        row["error"] = f"{type(exc).__name__}: {exc}"
    row["elapsed_s"] = round(time.perf_counter() - t0, 4)
    return row


def iter_results(jobs: Sequence[Job], backend: str = "local", *, address: str | None = None,
                 workers: int | None = None) -> Iterator[dict[str, Any]]:
    """Run ``jobs`` on ``backend``; yield each row as its job finishes."""
    if backend == "local":
        yield from _local(jobs, workers)
    elif backend == "ray":
        yield from _ray(jobs, address, workers)
    else:
        raise ValueError(f"unknown backend {backend!r}; known: {', '.join(BACKENDS)}")


def _local(jobs: Sequence[Job], workers: int | None) -> Iterator[dict[str, Any]]:
    n = workers or os.cpu_count() or 1
    if n < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if n == 1 or len(jobs) <= 1:
        for job in jobs:  # in-process: no pool start-up, easy to debug
            yield run_job(job)
        return
    # forkserver: workers fork from a clean server that has hdgym (and its compiled
    # kernels) imported, never from a parent holding threads (tqdm, Ray, BLAS)
    ctx = mp.get_context("forkserver")
    ctx.set_forkserver_preload(["hdgym.sweep.backends", "hdgym.sweep.scenarios", "hdgym.sim"])
    todo = iter(jobs)
    window = 4 * n
    pool = ProcessPoolExecutor(max_workers=min(n, len(jobs)), mp_context=ctx)
    try:
        pending: set[Future[dict[str, Any]]] = set()
        for job in todo:
            pending.add(pool.submit(run_job, job))
            if len(pending) >= window:
                break
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                for job in todo:
                    pending.add(pool.submit(run_job, job))
                    if len(pending) >= window:
                        break
                yield fut.result()
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


def _ray(jobs: Sequence[Job], address: str | None, workers: int | None
         ) -> Iterator[dict[str, Any]]:
    try:
        import ray
    except ImportError:
        raise RuntimeError('backend "ray" needs Ray: pip install "hdgym[ray]" '
                           '(or pip install "ray>=2.9")') from None
    started = False
    if not ray.is_initialized():
        if address:
            ray.init(address=address, log_to_driver=True)
        else:
            kw: dict[str, Any] = {"include_dashboard": False, "log_to_driver": True,
                                  "object_store_memory": 128 * 1024**2}
            if workers:
                kw["num_cpus"] = workers
            ray.init(**kw)
        started = True
    try:
        task = ray.remote(num_cpus=1, max_retries=1)(run_job)
        n = workers or int(ray.cluster_resources().get("CPU", 1))
        window = 4 * max(n, 1)
        todo = iter(jobs)
        pending = []
        for job in todo:
            pending.append(task.remote(job))
            if len(pending) >= window:
                break
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                for job in todo:
                    pending.append(task.remote(job))
                    if len(pending) >= window:
                        break
                yield ray.get(ref)
    except BaseException:
        for ref in locals().get("pending", []):
            ray.cancel(ref, force=True)
        raise
    finally:
        if started:
            ray.shutdown()
