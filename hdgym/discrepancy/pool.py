"""Run independent case diagnoses in worker processes (``--jobs``), results in input order."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from typing import Any

from hdgym.progress import bar


def ordered_map(fn: Callable[[Any], Any], items: Iterable[Any], jobs: int = 1,
                desc: str = "cases") -> Iterator[Any]:
    """``fn(item)`` for each item, yielded in the items' order, under a progress bar
    (``desc``: its label; one tick per item done).

    With ``jobs`` > 1 the calls run in that many worker processes (each case is seeded and
    independent, so the results are the same as one after the other; only the wall times
    per case reflect the sharing of the cores). ``fn`` must be picklable (a module-level
    function or a :func:`functools.partial` of one).
    """
    items = list(items)
    with bar(total=len(items), desc=desc, unit="case") as done:
        if jobs <= 1 or len(items) <= 1:
            for it in items:
                yield fn(it)
                done.update(1)
            return
        with ProcessPoolExecutor(max_workers=jobs) as ex:
            for r in ex.map(fn, items):
                yield r
                done.update(1)
