"""What moved between two versions of a results page: the numbers in their tables.

A command that rewrites a results page reads the page it replaces first and
appends :func:`moved_section`, so the page itself says which of its numbers
changed since the previous run (after a physics change, say) and by how much.

Tables are markdown tables. A row is matched by its place (the page's
headings with their numbers blanked, so a heading such as "Load step (20.9 N
m)" still matches when 20.9 moves), its first cell and its other cells that
are not numbers (but not the verdict columns "target", "met" and "result"), and its rank
among rows with that same key; a number is the leading number of a cell
("1,234 env-steps/s", "58 %: met", "-0.5", "inf").
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from pathlib import Path

__all__ = ["moved_section", "table_numbers"]

_NUMBER = re.compile(r"^\s*([-+]?(?:\d[\d,]*\.?\d*(?:[eE][-+]?\d+)?|inf|nan))(?![\w.])")
#: verdict columns: they may flip between runs, so they are no part of a row's key
_VERDICTS = ("target", "met", "result")
_DIGITS = re.compile(r"(?<![\w-])[-+]?\d[\d,.]*(?:[eE][-+]?\d+)?(?!\w)")


def _number(cell: str) -> float | None:
    m = _NUMBER.match(cell)
    if m is None:
        return None
    try:
        return float(m.group(1).replace(",", ""))
    except ValueError:
        return None


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def _tables(text: str) -> Iterator[tuple[str, list[str], list[list[str]]]]:
    """(place, header, rows) of each markdown table; place = the headings above it
    (below the page title)."""
    heads: dict[int, str] = {}
    lines = text.splitlines()
    k = 0
    while k < len(lines):
        line = lines[k]
        if line.startswith("#"):
            level = len(line) - len(line.lstrip("#"))
            heads = {lv: h for lv, h in heads.items() if lv < level}
            heads[level] = _DIGITS.sub("#", line.lstrip("#").strip())
        elif (line.startswith("|") and k + 1 < len(lines)
              and re.fullmatch(r"[\s|:-]+", lines[k + 1]) and "-" in lines[k + 1]):
            header = _cells(line)
            rows = []
            k += 2
            while k < len(lines) and lines[k].startswith("|"):
                rows.append(_cells(lines[k]))
                k += 1
            yield " / ".join(heads[lv] for lv in sorted(heads) if lv > 1), header, rows
            continue
        k += 1


def table_numbers(text: str) -> dict[tuple[str, str, str], float]:
    """``{(place, row, column): number}`` of every numeric cell in the page's tables.

    ``row`` is the row's key (first cell and its non-numeric cells but the verdicts,
    then ``#n`` for the n-th row with the same key in that table).
    """
    out: dict[tuple[str, str, str], float] = {}
    places: dict[str, int] = {}
    for place, header, rows in _tables(text):
        places[place] = places.get(place, 0) + 1
        if places[place] > 1:  # a second table under the same headings
            place = f"{place} ({places[place]})"
        seen: dict[str, int] = {}
        for cells in rows:
            key = " · ".join([cells[0]] + [
                c for c, h in zip(cells[1:], header[1:], strict=False)
                if c and _number(c) is None and h.lower() not in _VERDICTS])
            seen[key] = seen.get(key, 0) + 1
            row = key if seen[key] == 1 else f"{key} #{seen[key]}"
            for j, cell in enumerate(cells[1:], start=1):
                v = _number(cell)
                if v is not None:
                    col = header[j] if j < len(header) else str(j)
                    out[(place, row, col)] = v
    return out


def _fmt(v: float) -> str:
    return f"{v:.4g}"


def _change(before: float, after: float) -> tuple[float, str]:
    if math.isnan(before) or math.isnan(after) or math.isinf(before) or math.isinf(after):
        return math.inf, "—"
    if abs(before) <= 1e-9 * abs(after):  # from zero (or rounding noise): no ratio
        return math.inf, f"{after - before:+.3g}"
    rel = (after - before) / abs(before)
    return abs(rel), f"{100 * rel:+.3g} %"


def _without(text: str, title: str) -> str:
    """``text`` without its own section ``title`` (up to the next heading of that level)."""
    level = title.split(" ")[0]
    out, skip = [], False
    for line in text.splitlines():
        if line.strip() == title:
            skip = True
            continue
        if skip and line.startswith("#") and line.split(" ")[0] <= level:
            skip = False
        if not skip:
            out.append(line)
    return "\n".join(out)


def moved_section(before: str | Path | None, after: str, *, most: int = 15,
                  title: str = "## What moved since the previous run") -> str:
    """Markdown: the table numbers of ``after`` that differ from ``before`` (page text, or
    a path whose current content is the page being replaced; ``None`` or a missing file:
    no section), largest relative change first, at most ``most`` rows."""
    if isinstance(before, Path):
        if not before.is_file():
            return ""
        before = before.read_text()
    if before is None:
        return ""
    old, new = table_numbers(_without(before, title)), table_numbers(_without(after, title))
    common = [k for k in new if k in old]
    moved = []
    for k in common:
        a, b = old[k], new[k]
        if a != b and not (math.isnan(a) and math.isnan(b)):
            size, text = _change(a, b)
            moved.append((size, k, a, b, text))
    moved.sort(key=lambda m: -m[0])
    lines = [title, ""]
    gone, added = len(set(old) - set(new)), len(set(new) - set(old))
    lines.append(f"Against the page this run replaced: {len(moved)} of {len(common)} table "
                 f"numbers in both pages changed"
                 + (f"; {gone} numbers are no longer on the page" if gone else "")
                 + (f"; {added} are new" if added else "") + ".")
    if moved:
        lines += ["", ("The largest changes:" if len(moved) > most else "Every change:"), "",
                  "| where | row | column | before | after | change |",
                  "|---|---|---|---:|---:|---:|"]
        for _, (place, row, col), a, b, text in moved[:most]:
            lines.append(f"| {place} | {row} | {col} | {_fmt(a)} | {_fmt(b)} | {text} |")
    return "\n".join(lines) + "\n"
