"""Every README code block runs as written (with short settings), on its own and in order.

The README is the newcomer's path: its Python blocks each run in a fresh
interpreter (so none leans on another block's imports), its shell lines run in
order in a scratch folder laid out like a checkout. Long settings are shortened
by the exact substitutions in :data:`SHORT` (each must still match the README,
so an edit there is noticed here). The default run skips the commands in
:data:`HEAVY` (minutes each); ``pytest -m slow`` runs every line. Both check
that nothing was written outside ``runs/`` and that ``results/`` is untouched.
Also: the results table is ``hdgym results --list``, .ci/run runs the README's
test command, and the layout section names every top-level module.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()

#: exact README text -> the short setting the tests run instead
SHORT = {
    "verbose=1).learn(total_timesteps=2_048)":
        "verbose=0, n_steps=64, batch_size=64).learn(total_timesteps=64)",
    "n_steps=256).learn(total_timesteps=16_384)":
        "n_steps=2, batch_size=128).learn(total_timesteps=128)",
    "--total-timesteps 4096": "--total-timesteps 64 --n-envs 2",
    "--episodes 20": "--episodes 2",
}
#: commands that take minutes: run only with -m slow
HEAVY = ("hdgym bench", "hdgym numerics", "hdgym reproduce", "hdgym controllers",
         "hdgym diagnose", "hdgym sweep", "python -m agents.train", "python -m agents.evaluate",
         "python -m hdgym.discrepancy.realdata", "python -m pip")


def blocks(lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", README, flags=re.S)


def shorten(text: str) -> str:
    for old, new in SHORT.items():
        text = text.replace(old, new)
    return text


def shell_lines() -> list[str]:
    out = []
    for block in blocks("bash"):
        for line in block.splitlines():
            line = re.sub(r"\s{2,}#\s.*$", "", line).strip()  # a trailing comment
            if line and not line.startswith("#"):
                out.append(shorten(line))
    return out


def env() -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=str(ROOT), TQDM_DISABLE="1", MPLBACKEND="Agg")


def scratch(tmp: Path) -> Path:
    """A folder laid out like a checkout (the repo's folders linked, results/ empty)."""
    for name in ("agents", "controllers", "hdgym", "docs", "pyproject.toml"):
        (tmp / name).symlink_to(ROOT / name)
    (tmp / "results").mkdir()
    return tmp


def run_line(line: str, cwd: Path) -> None:
    """One README shell line: each `a && b` part, `hdgym` through this checkout's CLI."""
    for part in line.split(" && "):
        argv = shlex.split(part)
        if argv[:3] == ["python", "-m", "pip"] or argv[:2] == ["pip", "install"]:
            continue  # installing is what the fresh-clone check does, not a test
        if argv[:3] == ["python", "-m", "pytest"]:
            continue  # this is the test run
        if argv[0] == "hdgym":
            argv = [sys.executable, "-m", "hdgym.cli", *argv[1:]]
        elif argv[0] == "python":
            argv = [sys.executable, *argv[1:]]
        else:
            argv = ["bash", "-c", part]
        proc = subprocess.run(argv, cwd=cwd, env=env(), capture_output=True, text=True,
                              timeout=1800)
        ok = (0, 1) if part.startswith("hdgym reproduce") else (0,)  # 1: a check failed
        assert proc.returncode in ok, f"{part}\n{proc.stdout[-2000:]}\n{proc.stderr[-4000:]}"
        assert "Traceback" not in proc.stderr, f"{part}\n{proc.stderr[-4000:]}"


def check_clean(cwd: Path) -> None:
    """Only runs/ was written; results/ is untouched."""
    made = sorted(p.name for p in cwd.iterdir() if not p.is_symlink())
    assert made in (["results"], ["results", "runs"]), made
    assert list((cwd / "results").iterdir()) == []


def test_short_settings_still_match_the_readme():
    for old in SHORT:
        assert old in README, f"README no longer has {old!r}: update tests/test_readme.py"


@pytest.mark.parametrize("k", range(len(blocks("python"))))
def test_python_block_runs_on_its_own(k, tmp_path):
    code = shorten(blocks("python")[k])
    proc = subprocess.run([sys.executable, "-c", code], cwd=scratch(tmp_path), env=env(),
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, f"block {k}:\n{code}\n{proc.stderr[-4000:]}"
    check_clean(tmp_path)


def test_shell_lines_run_in_order(tmp_path):
    """Every line but the minutes-long ones (those run with -m slow)."""
    cwd = scratch(tmp_path)
    lines = [ln for ln in shell_lines() if not ln.startswith(HEAVY)]
    assert len(lines) >= 5
    for line in lines:
        run_line(line, cwd)
    check_clean(cwd)


@pytest.mark.slow
def test_every_shell_line_runs_in_order(tmp_path):
    cwd = scratch(tmp_path)
    for line in shell_lines():
        run_line(line, cwd)
    check_clean(cwd)


def test_results_table_is_hdgym_results_list():
    from hdgym.results_pages import table

    assert table() in README


def test_ci_runs_the_readme_test_command():
    line = next(ln for ln in blocks("bash")[0].splitlines() if "pytest" in ln)
    assert line.strip() in (ROOT / ".ci" / "run").read_text()


def test_layout_section_matches_the_tree():
    """The layout names every top-level module and package, and nothing that is gone."""
    layout = README[README.index("## Layout"):]
    names = ["controllers/", "agents/", "results/", "docs/", "tests/"]
    for p in sorted((ROOT / "hdgym").iterdir()):
        if p.name.startswith(("_", ".")):
            continue
        if p.suffix == ".py" or (p.is_dir() and (p / "__init__.py").exists()):
            names.append(f"hdgym/{p.name}" + ("/" if p.is_dir() else ""))
    missing = [n for n in names if n not in layout]
    assert not missing, f"README layout does not name {missing}"
    for path in re.findall(r"\b((?:hdgym|controllers|agents|docs)/[\w/.-]*)", layout):
        assert (ROOT / path).exists(), f"README layout names {path}, which is not in the tree"


def test_the_project_explains_itself():
    """No file points outside the repository: its physics notes are docs/physics.md, its data
    ship with their licence (issue 13 item 7)."""
    outside = ("PHYSICS.md", "DESIGN.md", "../shared", "shared/real-data", "/work/")
    files = [ROOT / "README.md", ROOT / "pyproject.toml", *(ROOT / "docs").glob("*.md")]
    for pkg in ("hdgym", "controllers", "agents"):
        files += [p for p in (ROOT / pkg).rglob("*") if p.suffix in (".py", ".toml", ".md")]
    for f in files:
        text = f.read_text()
        for word in outside:
            assert word not in text, f"{f.relative_to(ROOT)} mentions {word}"
    assert (ROOT / "docs" / "physics.md").is_file()
    data = ROOT / "hdgym" / "discrepancy" / "data" / "zxf17"
    assert (data / "LICENSE").is_file() and "MIT" in (data / "LICENSE").read_text()
    assert "MIT" in README and "harivin/harmonic-drive-actuator" in README
