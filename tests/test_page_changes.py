"""What moved between two versions of a results page (hdgym/page_changes.py)."""

from __future__ import annotations

from pathlib import Path

from hdgym.page_changes import moved_section, table_numbers

BEFORE = """\
# Bench

Made by `x`.

## Joint 1

### Load step (20.9 N m)

| controller | peak (arcsec) | speed | target |
|---|---|---|---|
| PID | 177.6 | 1,200 rev/s | ≥ 50 %: met |
| PID | 10 | 3 | |
| PID + DOB | 81.4 | inf | ≥ 50 %: met |

## Joint 3

| controller | peak (arcsec) |
|---:|---:|
| PID | 5.0 |
"""


def test_table_numbers_keys_rows_by_place_label_and_rank() -> None:
    nums = table_numbers(BEFORE)
    place = "Joint # / Load step (# N m)"  # numbers in headings are blanked
    assert nums[(place, "PID", "peak (arcsec)")] == 177.6
    assert nums[(place, "PID", "speed")] == 1200.0
    assert nums[(place, "PID #2", "speed")] == 3.0
    assert nums[(place, "PID + DOB", "speed")] == float("inf")
    assert nums[("Joint #", "PID", "peak (arcsec)")] == 5.0
    table = "| x | y |\n|---|---|\n| r | {} |\n"
    twice = table_numbers("## A\n\n" + table.format(1) + "\n" + table.format(2))
    assert twice == {("A", "r", "y"): 1.0, ("A (2)", "r", "y"): 2.0}
    assert (place, "PID", "target") not in nums  # "≥ 50 %" does not start with a number
    assert len(nums) == 7


def test_moved_section_names_each_change_and_survives_its_own_rerun(tmp_path: Path) -> None:
    after = (BEFORE.replace("(20.9 N m)", "(21.4 N m)").replace("| 177.6 |", "| 150.0 |")
             .replace("≥ 50 %: met |\n| PID | 10", "≥ 50 %: **not met** |\n| PID | 10")
             .replace("| PID | 5.0 |\n", ""))
    sec = moved_section(BEFORE, after)
    assert sec.startswith("## What moved since the previous run\n")
    assert "1 of 6 table numbers in both pages changed; 1 numbers are no longer on the page" in sec
    assert "| Joint # / Load step (# N m) | PID | peak (arcsec) | 177.6 | 150 | -15.5 % |" in sec
    page = tmp_path / "page.md"
    page.write_text(after + "\n" + sec)
    # the next run reads that page: its own "what moved" table is not part of the comparison
    again = moved_section(page, after)
    assert "0 of 6 table numbers in both pages changed." in again
    assert "| where |" not in again
    assert moved_section(tmp_path / "missing.md", after) == ""
    assert moved_section(None, after) == ""


def test_bench_page_names_load_missing_sections_and_what_moved(tmp_path: Path) -> None:
    from hdgym.bench import write_report

    page = tmp_path / "bench.md"
    row = {"name": "physics, 1 env", "value": 1000.0, "unit": "env-steps/s",
           "reference": "bare loop", "reference_value": 2000.0, "ratio": 0.5, "target": "",
           "met": None}
    write_report({"Physics": [row]}, page, "hdgym bench", load=("0.5 on 2 cores", "1.0 on 2 cores"))
    first = page.read_text()
    assert "Load average 0.5 on 2 cores at the start, 1.0 on 2 cores at the end" in first
    assert "What moved" not in first  # nothing to compare with yet
    write_report({"Physics": [{**row, "value": 1500.0, "ratio": 0.75}]}, page, "hdgym bench",
                 not_measured={"agents": "cannot import agents.bench (ImportError: no SB3)"})
    second = page.read_text()
    assert "Not measured: the sections of `agents` (cannot import agents.bench" in second
    assert "| Physics | physics, 1 env · bare loop | value | 1000 | 1500 | +50 % |" in second
    assert "| Physics | physics, 1 env · bare loop | ratio | 0.5 | 0.75 | +50 % |" in second


def test_a_change_from_zero_or_rounding_noise_is_given_as_a_difference() -> None:
    page = "## S\n\n| m | std |\n|---|---|\n| a | {} |\n"
    sec = moved_section(page.format("1.17e-16"), page.format("0.01667"))
    assert "| S | a | std | 1.17e-16 | 0.01667 | +0.0167 |" in sec
