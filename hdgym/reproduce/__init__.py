"""The fidelity suite: ``hdgym reproduce tuttle|seyfferth|all``.

Each paper is a module with one function per item (:mod:`.tuttle`,
:mod:`.seyfferth`) and registers a :class:`~hdgym.reproduce.common.Paper`
in :data:`PAPERS`; ``all`` runs every registered paper. The analysis
functions the items use live in :mod:`.analysis` (plain functions on
arrays, reused by tests); the :class:`~hdgym.reproduce.common.Item` record
and the page writer in :mod:`.common`.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from hdgym.reproduce import seyfferth, tuttle
from hdgym.reproduce.analysis import (
    LoopMetrics,
    OrderSpectrum,
    PlateauResult,
    RunUp,
    StepRuns,
    frequency_response,
    grows_smoothly,
    ke_order_spectrum,
    loop_metrics,
    plateau_jump,
    plateau_near,
    resonance_peak,
    run_up,
    starting_current,
    step_runs,
    step_table,
)
from hdgym.reproduce.common import Check, Item, Paper, echo_items, run_items, write_page

#: the registered papers, in page order
PAPERS: dict[str, Paper] = {p.name: p for p in (tuttle.PAPER, seyfferth.PAPER)}
#: the ``hdgym reproduce`` choices
CHOICES = (*PAPERS, "all")


def run(which: str, out: Path, quick: bool = False, echo: Callable[[str], None] | None = print
        ) -> bool:
    """Run one paper's items (or ``all``), write ``out/fidelity.md`` and the figures, and
    print each item's checks (the paper's passage and number, the tolerance, the model's
    number, PASS/FAIL) through ``echo`` (None: silent).

    Returns True if every item passed.

    Raises:
        ValueError: for an unknown paper, naming the known ones.
    """
    if which not in CHOICES:
        raise ValueError(f"reproduce: unknown study {which!r}; known: {', '.join(CHOICES)}")
    papers = list(PAPERS.values()) if which == "all" else [PAPERS[which]]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    results = [(paper, run_items(paper, out, quick)) for paper in papers]
    if echo is not None:
        for _, items in results:
            echo_items(items, echo)
    write_page(out, f"hdgym reproduce {which} --out {out}", results, quick)
    return all(it.passed for _, items in results for it in items)


__all__ = [
    "CHOICES", "Check", "Item", "LoopMetrics", "OrderSpectrum", "PAPERS", "Paper", "PlateauResult",
    "RunUp", "StepRuns", "echo_items", "frequency_response", "grows_smoothly", "ke_order_spectrum",
    "loop_metrics", "plateau_jump", "plateau_near", "resonance_peak", "run", "run_up",
    "starting_current", "step_runs", "step_table",
]
