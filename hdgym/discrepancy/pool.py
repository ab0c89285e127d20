"""Run independent case diagnoses in worker processes (``--jobs``), results in input order."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor
from typing import Any

from hdgym.progress import bar


def call_all(calls: Sequence[Callable[[], Any]], jobs: int = 1,
             desc: str = "cases") -> Iterator[Any]:
    """``call()`` for each call, yielded in the calls' order, under a progress bar (``desc``:
    its label; one tick per call done).

    With ``jobs`` > 1 every call is queued at once on one pool of that many worker processes,
    so a page made of several sets of cases never waits for one set's slowest case with
    a core idle before the next set starts (each case is seeded and independent, so the
    results are the same as one after the other; only the wall times per case reflect the
    sharing of the cores). Each call must be picklable (a :func:`functools.partial` of a
    module-level function).
    """
    calls = list(calls)
    with bar(total=len(calls), desc=desc, unit="case") as done:
        if jobs <= 1 or len(calls) <= 1:
            for call in calls:
                yield call()
                done.update(1)
            return
        with ProcessPoolExecutor(max_workers=min(jobs, len(calls))) as ex:
            futures = [ex.submit(call) for call in calls]
            for f in futures:
                yield f.result()
                done.update(1)
