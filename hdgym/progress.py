"""Progress for long jobs: a tqdm bar on stderr, and a line when numba compiles.

Use :func:`bar` around any loop that may run over a few seconds::

    from hdgym.progress import bar
    for item in bar(items, "controllers"):
        ...

and :func:`step` for a job made of a few unequal parts::

    with bar(total=3, desc="reproduce") as b:
        part_one(); step(b, "part two")
        ...

Bars go to stderr, so stdout stays the command's result. ``TQDM_DISABLE=1``
switches them off (tqdm's own environment setting). :func:`announce_compiles`
prints one line the first time numba compiles in this process (a cold cache:
the first run after installing or after a physics change); later runs load the
compiled code from numba's cache and say nothing.
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterable, Iterator
from typing import Any, TypeVar

from tqdm import tqdm

__all__ = ["COMPILE_MESSAGE", "announce_compiles", "bar", "step"]

T = TypeVar("T")

COMPILE_MESSAGE = ("compiling the physics with numba (first run after an install or a change; "
                   "cached afterwards, about 20-60 s) ...")


def bar(iterable: Iterable[T] | None = None, desc: str = "", total: int | None = None,
        unit: str = "it", leave: bool = False, **kwargs: Any) -> tqdm:
    """A tqdm progress bar on stderr (``desc`` names the job, ``unit`` its items)."""
    return tqdm(iterable, desc=desc, total=total, unit=unit, leave=leave, file=sys.stderr,
                dynamic_ncols=True, mininterval=0.5, **kwargs)


def step(b: tqdm, what: str) -> None:
    """Advance ``b`` by one and show ``what`` comes next."""
    b.set_postfix_str(what, refresh=False)
    b.update(1)


@contextlib.contextmanager
def announce_compiles() -> Iterator[None]:
    """Within the block, say (once) when numba starts compiling (cache misses only)."""
    from numba.core import event

    class CompileNotice(event.Listener):
        said = False

        def on_start(self, ev: Any) -> None:
            if not self.said:
                self.said = True
                tqdm.write(COMPILE_MESSAGE, file=sys.stderr)

        def on_end(self, ev: Any) -> None:
            pass

    with event.install_listener("numba:compile", CompileNotice()):
        yield
