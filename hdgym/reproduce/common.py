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

from hdgym.page_changes import moved_section
from hdgym.params import JointParams, atomic_write_text


def verdict(ok: bool) -> str:
    """PASS or FAIL, as the fidelity pages print it."""
    return "PASS" if ok else "FAIL"


@dataclass(frozen=True)
class Check:
    """One observable, the paper beside the model.

    Attributes:
        observable: what is compared (``joint 2: plateau near 10,000 °/s``).
        passage: the paper's words, with section and page.
        paper: the paper's number (text: units included).
        tolerance: the band the model's number must fall in.
        model: the model's number.
        passed: whether it does.
    """

    observable: str
    passage: str
    paper: str
    tolerance: str
    model: str
    passed: bool

    def line(self) -> str:
        """One line for the terminal."""
        return (f"{self.observable}: paper {self.paper} ({self.passage}); tolerance "
                f"{self.tolerance}; model {self.model}: {verdict(self.passed)}")


@dataclass
class Item:
    """One item of the fidelity page.

    Attributes:
        key: short label (``T3``).
        title: what the item reproduces.
        criterion: how it is judged, in words.
        measured: free-text lines of what the model did (tables, ablations).
        passed: the verdict (all checks passed, where the item has checks).
        figures: file names of its figures, beside the page.
        checks: the side-by-side rows (paper, tolerance, model).
        role: which calibrated numbers were tuned on this item, or that none were
            (a held-out check).
    """

    key: str
    title: str
    criterion: str
    measured: list[str] = field(default_factory=list)
    passed: bool = False
    figures: list[str] = field(default_factory=list)
    checks: list[Check] = field(default_factory=list)
    role: str = ""

    def check(self, observable: str, passage: str, paper: str, tolerance: str, model: str,
              passed: bool) -> bool:
        """Add a :class:`Check`; returns ``passed``."""
        self.checks.append(Check(observable, passage, paper, tolerance, model, bool(passed)))
        return bool(passed)


def within(value: float, reference: float, tol: float) -> bool:
    """Whether ``value`` is within the relative tolerance ``tol`` of ``reference``.

    The bound is inclusive up to rounding: 4.25 Hz against 5 Hz ±15 % passes
    (``abs(4.25 / 5 - 1)`` is 0.15000000000000002 in floating point).
    """
    return bool(abs(value / reference - 1.0) <= tol * (1.0 + 1e-9))


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
    """Write ``out/fidelity.md``: the paper and the model side by side, then each item."""
    cmd = command + (" --quick" if quick else "")
    presets = ", ".join(f"`{n}`" for paper, _ in results for n in paper.presets)
    everything = [it for _, items in results for it in items]
    n_pass = sum(it.passed for it in everything)
    lines = [
        "# Fidelity: hdgym against the papers",
        "",
        f"Regenerate with `{cmd}`. Deterministic (fixed seeds).",
        f"Presets: {presets}. Each number a preset takes from a paper, and each number it "
        "calibrates (and on which item), is in the preset's `[sources]` table; the equations "
        "are in docs/physics.md.",
        "",
        f"**{n_pass} of {len(everything)} items pass"
        + (" (all)**" if n_pass == len(everything) else "**"),
        "",
        "| item | observable | the paper says | paper | tolerance | model | result |",
        "|---|---|---|---|---|---|---|",
    ]
    for it in everything:
        if not it.checks:
            lines.append(f"| ({it.key}) {it.title} | see below | | | | | "
                         f"{verdict(it.passed)} |")
        for c in it.checks:
            lines.append(f"| ({it.key}) | {c.observable} | {c.passage} | {c.paper} | "
                         f"{c.tolerance} | {c.model} | {verdict(c.passed)} |")
    lines.append("")
    for paper, items in results:
        lines += [f"## {paper.title}", ""]
        for it in items:
            lines += [f"### ({it.key}) {it.title}: {verdict(it.passed)}", ""]
            if it.role:
                lines += [f"Calibration: {it.role}", ""]
            lines += [f"Criterion: {it.criterion}.", "", "Measured:", ""]
            lines += [f"- {m}" for m in it.measured]
            lines.append("")
            lines += [f"![{it.key}]({fig})" for fig in it.figures]
            lines.append("")
    text = "\n".join(lines) + "\n"
    # what this run changed against the page it replaces (after a physics change, say)
    moved = moved_section(out / "fidelity.md", text)
    atomic_write_text(out / "fidelity.md", text + ("\n" + moved if moved else ""))


def echo_items(items: Sequence[Item], echo: Callable[[str], None] = print) -> None:
    """Print each item's verdict and its side-by-side checks."""
    for it in items:
        echo(f"({it.key}) {it.title}: {verdict(it.passed)}")
        for c in it.checks:
            echo(f"    {c.line()}")
