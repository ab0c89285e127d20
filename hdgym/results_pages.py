"""The committed results pages, in build order, each with the command that makes it.

``hdgym results`` runs these commands in order (physics first, then what
builds on it); ``hdgym results --quick`` runs their quick variants into
``runs/results-quick/`` (quick runs never write into results/). The README's
results table is :func:`table` (a test holds them equal). A page is added
here, by the helper that owns it, with the command that regenerates it.

The commands are data (argument lists): ``{root}`` stands for the output root
(``results`` for the committed pages).
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass

__all__ = ["PAGES", "Page", "table"]


@dataclass(frozen=True)
class Page:
    """One results page.

    Attributes:
        name: short name (``hdgym results --only NAME``).
        path: the page, relative to the output root (e.g. ``bench.md``).
        what: what it shows, one line.
        argv: the command, as run (``hdgym ...`` or ``python -m ...``), with
            ``{root}`` for the output root.
        quick: extra arguments for the quick variant (``None``: the command
            is already quick enough and runs as it is).
        written_codes: exit codes after which the page is written (a
            reproduce page with a failed check exits 1 and says so on the page).
    """

    name: str
    path: str
    what: str
    argv: tuple[str, ...]
    quick: tuple[str, ...] | None = ("--quick",)
    written_codes: tuple[int, ...] = (0,)

    def command(self, root: str = "results", quick: bool = False) -> list[str]:
        """The command line for output root ``root``."""
        argv = [a.replace("{root}", root) for a in self.argv]
        if quick and self.quick:
            argv += list(self.quick)
        return argv

    def shown(self, root: str = "results") -> str:
        """The command as a user types it."""
        return shlex.join(self.command(root))


PAGES: tuple[Page, ...] = (
    Page("fidelity", "fidelity/fidelity.md", "published measurements reproduced (Tuttle 1992; "
         "Seyfferth et al. and seed 002)",
         ("hdgym", "reproduce", "all", "--out", "{root}/fidelity"), written_codes=(0, 1)),
    Page("numerics", "numerics.md", "substep convergence per preset",
         ("hdgym", "numerics", "--out", "{root}/numerics.md")),
    Page("bench", "bench.md", "speed, as ratios against references measured in the same run "
         "(with the million-step soak runs)",
         ("hdgym", "bench", "--soak", "--out", "{root}/bench.md")),
    Page("controllers", "controllers.md", "controller benchmark (figures in controllers/)",
         ("hdgym", "controllers", "--out", "{root}")),
    Page("sweep-controllers", "sweeps/controllers.md",
         "the controller benchmark across ±30 % drives",
         ("hdgym", "sweep", "controllers", "--out", "{root}/sweeps/controllers-run",
          "--summary-dir", "{root}/sweeps")),
    Page("sweep-rl", "sweeps/rl.md", "the PPO agent across training seeds",
         ("hdgym", "sweep", "rl", "--out", "{root}/sweeps/rl-run", "--summary-dir",
          "{root}/sweeps")),
    Page("discrepancy", "discrepancy.md", "hidden-effect cases for the diagnosis workflow",
         ("python", "-m", "hdgym.discrepancy.cases", "--out", "{root}/discrepancy.md")),
    Page("real-data", "real-data/report.md", "diagnosis of real ZXF17 strain-wave measurements",
         ("python", "-m", "hdgym.discrepancy.realdata", "--out", "{root}/real-data")),
    Page("rl", "rl/evaluation.md", "RL policy against tuned classical controllers",
         ("python", "-m", "agents.report", "--out", "{root}/rl"),
         ("--episodes", "4", "--check-episodes", "0")),
)


def table(root: str = "results") -> str:
    """The README's results table (markdown)."""
    lines = ["| page | what | command |", "|---|---|---|"]
    lines += [f"| `{root}/{p.path}` | {p.what} | `{p.shown(root)}` |" for p in PAGES]
    return "\n".join(lines)
