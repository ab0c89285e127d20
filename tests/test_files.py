"""Output files: usual permissions, nothing half-written, the results/ guard (issue 13: 2, 4)."""

from __future__ import annotations

import os
import stat

import pytest

from hdgym.files import atomic_path, atomic_write_text, check_out, in_results, umask_mode


@pytest.fixture
def umask022():
    old = os.umask(0o022)
    yield
    os.umask(old)


def mode(p) -> int:
    return stat.S_IMODE(os.stat(p).st_mode)


def test_atomic_files_get_the_umask_mode(tmp_path, umask022):
    atomic_write_text(tmp_path / "a" / "x.md", "hello\n")
    assert (tmp_path / "a" / "x.md").read_text() == "hello\n"
    assert mode(tmp_path / "a" / "x.md") == 0o644 and mode(tmp_path / "a") == 0o755
    os.umask(0o077)
    atomic_write_text(tmp_path / "y.md", "y")
    assert mode(tmp_path / "y.md") == 0o600 == umask_mode()
    assert umask_mode(directory=True) == 0o700


def test_cli_outputs_get_the_umask_mode(tmp_path, umask022):
    from hdgym.cli import main

    rec, toml = tmp_path / "r" / "run.csv", tmp_path / "j.toml"
    assert main(["simulate", "--preset", "tuttle-joint1", "--command", "step:1",
                 "--duration", "0.05", "--out", str(rec)]) == 0
    assert main(["params", "--preset", "tuttle-joint1", "--out", str(toml)]) == 0
    assert mode(rec) == mode(toml) == 0o644 and mode(rec.parent) == 0o755


def test_interrupted_write_leaves_nothing(tmp_path):
    target = tmp_path / "page.md"
    target.write_text("old")
    with pytest.raises(KeyboardInterrupt), atomic_path(target) as tmp:
        tmp.write_text("half")
        raise KeyboardInterrupt
    assert target.read_text() == "old" and sorted(os.listdir(tmp_path)) == ["page.md"]


def test_results_guard(tmp_path):
    (tmp_path / "pyproject.toml").write_text("")
    assert in_results(tmp_path / "results" / "bench.md")
    assert not in_results(tmp_path / "runs" / "results-quick" / "bench.md")
    assert not in_results(tmp_path / "elsewhere" / "results" / "x")  # not a checkout's results/
    check_out(tmp_path / "results" / "x.md", quick=False)
    with pytest.raises(ValueError, match="quick runs never write into results/"):
        check_out(tmp_path / "results" / "x.md", quick=True)


def test_compile_notice_once_per_block(capsys):
    """Progress (issue 13 item 3): a numba compile inside the block is announced, once."""
    import numba

    from hdgym.progress import COMPILE_MESSAGE, announce_compiles, bar

    @numba.njit
    def f(x):
        return x + 1

    @numba.njit
    def g(x):
        return x * 2

    with announce_compiles():
        f(1)
        g(1.0)
    f(2.0)  # outside the block: a new compile says nothing
    err = capsys.readouterr().err
    assert err.count(COMPILE_MESSAGE) == 1
    assert sum(bar(range(3), "x")) == 3


LONG_JOBS = ["hdgym/reproduce/common.py", "hdgym/numerics.py", "hdgym/bench.py",
             "hdgym/discrepancy/workflow.py", "controllers/benchmark.py", "hdgym/sweep/runner.py",
             "hdgym/reproduce/calibration.py", "hdgym/discrepancy/pool.py"]


@pytest.mark.parametrize("path", LONG_JOBS)
def test_long_jobs_show_progress(path):
    """controllers, diagnose, reproduce, bench, numerics, sweep, the calibration scan loop
    and the discrepancy pages' case loop (python -m hdgym.discrepancy.cases / .holdout)
    under a bar: each calls hdgym.progress's ``bar`` (imported is not enough). Behaviour: the
    reproduce bar below, the sweep's in tests/test_sweep.py."""
    import ast
    from pathlib import Path

    tree = ast.parse((Path(__file__).parents[1] / path).read_text())
    names = {a.asname or a.name for node in ast.walk(tree)
             if isinstance(node, ast.ImportFrom) and node.module == "hdgym.progress"
             for a in node.names if a.name == "bar"}
    assert names, f"{path} does not import hdgym.progress.bar"
    called = {node.func.id for node in ast.walk(tree)
              if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)}
    assert names & called, f"{path} imports hdgym.progress.bar but never calls it"


def test_reproduce_items_run_under_a_bar(tmp_path, capsys):
    import time

    if os.environ.get("TQDM_DISABLE"):
        pytest.skip("progress bars switched off (TQDM_DISABLE)")

    from hdgym.reproduce.common import Item, Paper, run_items

    def slow_item(out, quick):
        time.sleep(0.6)  # past the bar's refresh interval
        return Item("a", "x", "y", ["z"], True)

    items = run_items(Paper("demo", "Demo", (), (slow_item, slow_item)), tmp_path, True)
    assert [i.passed for i in items] == [True, True]
    assert "reproduce demo" in capsys.readouterr().err
