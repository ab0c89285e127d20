"""Run independent case diagnoses in worker processes (``--jobs``), results in input order."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ProcessPoolExecutor
from typing import Any


def ordered_map(fn: Callable[[Any], Any], items: Iterable[Any], jobs: int = 1) -> Iterator[Any]:
    """``fn(item)`` for each item, yielded in the items' order.

    With ``jobs`` > 1 the calls run in that many worker processes (each case is seeded and
    independent, so the results are the same as one after the other; only the wall times
    per case reflect the sharing of the cores). ``fn`` must be picklable (a module-level
    function or a :func:`functools.partial` of one).
    """
    items = list(items)
    if jobs <= 1 or len(items) <= 1:
        for it in items:
            yield fn(it)
        return
    with ProcessPoolExecutor(max_workers=jobs) as ex:
        yield from ex.map(fn, items)
