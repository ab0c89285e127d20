"""What every paper's items share: the :class:`Item` record, figures, the page.

A paper module (:mod:`hdgym.reproduce.tuttle`, :mod:`hdgym.reproduce.seyfferth`)
exposes a :class:`Paper`: its title, the presets it uses and one function
per item ``(out_dir, quick) -> Item``. :func:`run_papers` runs the items of
the chosen papers, catches a crashing item as a FAIL, and writes one page
``fidelity.md`` with the figures beside it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hdgym.params import JointParams, atomic_write_text

# ===================================================================== the study


@dataclass
class Item:
    """One line of the fidelity page."""

    key: str
    title: str
    criterion: str
    measured: list[str] = field(default_factory=list)
    passed: bool = False
    figures: list[str] = field(default_factory=list)


def plt_module() -> Any:
    """``matplotlib.pyplot`` on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def simulator(p: JointParams, **kw: Any) -> Any:
    """A :class:`hdgym.sim.Simulator` (imported late: the Record type lives in hdgym.record)."""
    from hdgym.sim import Simulator

    return Simulator(p, **kw)


def finish(item: Item, fig: Any, path: Path, ok: bool) -> Item:
    """Save the item's figure next to the page and record the verdict."""
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt_module().close(fig)
    item.figures.append(path.name)
    item.passed = bool(ok)
    return item


@dataclass(frozen=True)
class Paper:
    """One paper's fidelity items.

    Attributes:
        name: the ``hdgym reproduce`` choice (``tuttle``).
        title: the page section title.
        presets: the presets its items use (named on the page).
        items: one function per item, ``(out_dir, quick) -> Item``.
    """

    name: str
    title: str
    presets: tuple[str, ...]
    items: tuple[Callable[[Path, bool], Item], ...]


def run_items(paper: Paper, out: Path, quick: bool) -> list[Item]:
    """Every item of ``paper``; an item that raises is reported as a FAIL, not fatal."""
    from hdgym.progress import bar

    items = []
    for k, check in enumerate(bar(paper.items, f"reproduce {paper.name}", unit="item")):
        try:
            items.append(check(out, quick))
        except Exception as exc:  # a failing check is reported, not fatal to the page
            doc = (check.__doc__ or check.__name__).strip().splitlines()[0].rstrip(".")
            items.append(Item(f"{paper.name}-{k + 1}", doc, "see the code",
                              [f"error: {type(exc).__name__}: {exc}"], False))
    return items


def write_page(out: Path, command: str, results: Sequence[tuple[Paper, list[Item]]],
               quick: bool) -> None:
    """Write ``out/fidelity.md``: a summary table, then each paper's items."""
    cmd = command + (" --quick" if quick else "") + f" --out {out}"
    presets = ", ".join(f"`{n}`" for paper, _ in results for n in paper.presets)
    everything = [it for _, items in results for it in items]
    lines = [
        "# Fidelity: hdgym against the papers",
        "",
        f"Regenerate with `{cmd}`. Deterministic (fixed seeds).",
        f"Presets: {presets}; the numbers chosen to reproduce these observations are "
        "documented in each preset's `[sources]` table.",
        "",
        "| item | result |",
        "|---|---|",
    ]
    for it in everything:
        lines.append(f"| ({it.key}) {it.title} | {'PASS' if it.passed else 'FAIL'} |")
    lines.append("")
    lines.append(f"**Overall: {'PASS' if all(i.passed for i in everything) else 'FAIL'}**")
    lines.append("")
    for paper, items in results:
        lines += [f"## {paper.title}", ""]
        for it in items:
            lines += [f"### ({it.key}) {it.title}: {'PASS' if it.passed else 'FAIL'}", "",
                      f"Criterion: {it.criterion}.", "", "Measured:", ""]
            lines += [f"- {m}" for m in it.measured]
            lines.append("")
            lines += [f"![{it.key}]({fig})" for fig in it.figures]
            lines.append("")
    atomic_write_text(out / "fidelity.md", "\n".join(lines))
