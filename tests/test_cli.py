"""The `hdgym` command: success paths and one-line errors with exit code 2."""

from __future__ import annotations

import subprocess
import sys

import pytest

from hdgym.cli import main
from hdgym.params import load, preset
from hdgym.record import read_record


def test_simulate_writes_record(tmp_path):
    out = tmp_path / "run.csv"
    assert main(["simulate", "--preset", "tuttle-joint1", "--command", "step:3.2",
                 "--duration", "0.2", "--out", str(out)]) == 0
    rec = read_record(out)
    assert len(rec) == 200 and rec.meta["preset"] == "tuttle-joint1"
    assert rec.current_command[0] == 3.2


def test_simulate_locked_without_effect(tmp_path):
    out = tmp_path / "loop.csv"
    assert main(["simulate", "--preset", "tuttle-joint2", "--locked-output", "--without",
                 "hysteresis", "--command", "sine:2:2", "--duration", "0.5",
                 "--out", str(out)]) == 0
    assert read_record(out).locked_output


def test_params_round_trip(tmp_path):
    out = tmp_path / "j.toml"
    assert main(["params", "--preset", "tuttle-joint3", "--out", str(out)]) == 0
    assert load(out) == preset("tuttle-joint3")


@pytest.mark.parametrize("argv, words", [
    (["simulate", "--preset", "nope", "--command", "step:1", "--duration", "1", "--out", "x.csv"],
     "unknown preset 'nope'"),
    (["simulate", "--preset", "tuttle-joint1", "--without", "magic", "--command", "step:1",
      "--duration", "1", "--out", "x.csv"], "unknown effect 'magic'"),
    (["simulate", "--preset", "tuttle-joint1", "--command", "step:x", "--duration", "1",
      "--out", "x.csv"], "'x' is not a number"),
    (["simulate", "--params", "missing.toml", "--command", "step:1", "--duration", "1",
      "--out", "x.csv"], "missing.toml"),
])
def test_bad_input_is_one_line_exit_2(tmp_path, argv, words):
    proc = subprocess.run([sys.executable, "-m", "hdgym.cli", *argv], cwd=tmp_path,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and words in lines[0], proc.stderr
    assert not (tmp_path / "x.csv").exists()
