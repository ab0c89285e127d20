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


# --- results/ policy (issue 13 item 2, issue 16 item 5) ---------------------------------------

OUT_COMMANDS = ["bench", "numerics", "reproduce", "controllers", "sweep", "results"]


def _fake_repo(tmp_path):
    """A folder that looks like a checkout: pyproject.toml beside results/."""
    (tmp_path / "pyproject.toml").write_text("[project]\nname = 'x'\n")
    (tmp_path / "results").mkdir()
    return tmp_path / "results"


def test_no_command_defaults_into_results():
    from hdgym.cli import build_parser

    ap = build_parser()
    sub = next(a for a in ap._actions if a.dest == "cmd")
    for name, sp in sub.choices.items():
        for action in sp._actions:
            if action.dest == "out" and action.default is not None:
                assert not str(action.default).startswith("results"), (name, action.default)


@pytest.mark.parametrize("argv", [
    ["bench", "--quick"], ["numerics", "--quick"], ["reproduce", "tuttle", "--quick"],
    ["controllers", "--quick"], ["sweep", "open-loop", "--quick"], ["results", "--quick"],
])
def test_quick_runs_refuse_results(tmp_path, capsys, argv):
    results = _fake_repo(tmp_path)
    out = results / ("x.md" if argv[0] in ("bench", "numerics") else "x")
    assert main([*argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "quick runs never write into results/" in err[0]
    assert list(results.iterdir()) == []


def test_quick_sweep_refuses_a_summary_dir_in_results(tmp_path, capsys):
    results = _fake_repo(tmp_path)
    assert main(["sweep", "open-loop", "--quick", "--out", str(tmp_path / "runs"),
                 "--summary-dir", str(results / "sweeps")]) == 2
    assert "summary_dir" in capsys.readouterr().err
    assert list(results.iterdir()) == [] and not (tmp_path / "runs").exists()


def test_bundled_specs_keep_summaries_out_of_results():
    from hdgym.sweep import load_spec, spec_names, spec_path

    for name in spec_names():
        assert load_spec(spec_path(name)).summary_dir is None, name


def test_results_list_and_bad_page(capsys):
    from hdgym.results_pages import PAGES, table

    assert main(["results", "--list"]) == 0
    assert capsys.readouterr().out.strip() == table()
    for page in PAGES:  # every page's command writes under the root it is given
        assert any("{root}" in a for a in page.argv), page.name
    assert main(["results", "--only", "nope", "--out", "runs/x"]) == 2
    assert "unknown page 'nope'" in capsys.readouterr().err


def test_results_runs_the_pages_in_order(tmp_path, monkeypatch, capsys):
    """`hdgym results` runs each page's command and stops at the first failure."""
    import subprocess as sp

    from hdgym import results_pages

    ran = []

    def fake_run(cmd, *a, **k):
        ran.append(cmd)
        return sp.CompletedProcess(cmd, 1 if len(ran) == 2 else 0)

    monkeypatch.setattr(sp, "run", fake_run)
    out = tmp_path / "r"
    assert main(["results", "--out", str(out)]) == 1
    assert len(ran) == 2 and ran[0][:3] == [sys.executable, "-m", "hdgym.cli"]
    assert ran[0][3:] == results_pages.PAGES[0].command(str(out))[1:]
    assert "numerics" in capsys.readouterr().err
    ran.clear()
    assert main(["results", "--quick", "--only", "rl", "--out", str(out)]) == 0
    assert ran == [[sys.executable, "-m", "agents.report", "--out", f"{out}/rl",
                    "--episodes", "4", "--check-episodes", "0"]]


# --- help texts (issue 13 item 8) -------------------------------------------------------------

def _help(argv, capsys):
    with pytest.raises(SystemExit):
        main([*argv, "--help"])
    return " ".join(capsys.readouterr().out.split())  # argparse wraps lines


def test_help_texts(capsys):
    from hdgym.discrepancy.experiments import PROTOCOLS
    from hdgym.sweep import spec_names

    top = _help([], capsys)
    assert "simulate" in top and "rebuild every results page" in top and "runs/" in top
    exp = _help(["experiment"], capsys)
    assert all(name in exp for name in PROTOCOLS)
    sweep = _help(["sweep"], capsys)
    assert "[spreads]" in sweep and all(name in sweep for name in spec_names())
    for cmd in OUT_COMMANDS:
        text = _help([cmd] + (["tuttle"] if cmd == "reproduce" else []), capsys)
        assert "--quick" in text and "never into results/" in text, cmd
        assert "--out" in text, cmd


def test_params_without_out_prints_toml(capsys):
    from hdgym.params import loads

    assert main(["params", "--preset", "tuttle-joint1"]) == 0
    assert loads(capsys.readouterr().out) == preset("tuttle-joint1")
    assert main(["params"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("hdgym params: give --preset") and "params: params" not in err


# --- agents.train on a fresh [rl] install (issue 13 item 1) -----------------------------------

def test_rl_extra_has_what_the_progress_bar_needs():
    import tomllib
    from pathlib import Path

    pytest.importorskip("stable_baselines3")
    from stable_baselines3.common.callbacks import ProgressBarCallback

    py = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())
    rl = " ".join(py["project"]["optional-dependencies"]["rl"])
    assert "rich" in rl and "tqdm" in rl
    ProgressBarCallback()  # raises ImportError without rich and tqdm


@pytest.mark.parametrize("exc, code", [(RuntimeError("boom"), None), (KeyboardInterrupt(), 130)])
def test_train_crash_leaves_no_run_folder(tmp_path, monkeypatch, capsys, exc, code):
    pytest.importorskip("stable_baselines3")
    from agents import train as train_mod

    def crash(cfg, out, progress=True):
        (out / "monitor").mkdir(parents=True)
        (out / "tb").mkdir()
        raise exc

    monkeypatch.setattr(train_mod, "train", crash)
    out = tmp_path / "run"
    if code is None:
        with pytest.raises(RuntimeError):
            train_mod.main(["--algo", "ppo", "--out", str(out)])
    else:
        assert train_mod.main(["--algo", "ppo", "--out", str(out)]) == code
        assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert not out.exists()


# --- one clear line (issue 13 item 6) ---------------------------------------------------------

def _one_line(capsys):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


def test_huge_duration_is_one_line(tmp_path, capsys):
    out = tmp_path / "x.csv"
    assert main(["simulate", "--preset", "tuttle-joint1", "--command", "step:1",
                 "--duration", "1e9", "--out", str(out)]) == 2
    assert "control periods" in _one_line(capsys) and not out.exists()


def test_toml_with_a_string_number_names_the_field(tmp_path, capsys):
    good = tmp_path / "j.toml"
    assert main(["params", "--preset", "tuttle-joint1", "--out", str(good)]) == 0
    bad = tmp_path / "bad.toml"
    bad.write_text(good.read_text().replace("resistance = 3.4", 'resistance = "3.4"', 1))
    assert main(["simulate", "--params", str(bad), "--command", "step:1", "--duration", "0.1",
                 "--out", str(tmp_path / "x.csv")]) == 2
    assert "motor.resistance must be a number, got '3.4'" in _one_line(capsys)


def test_params_output_documents_the_defaults(capsys):
    from dataclasses import MISSING, fields

    from hdgym.params.parts import PARTS

    assert main(["params", "--preset", "tuttle-joint1"]) == 0
    head = " ".join(line.lstrip("# ") for line in capsys.readouterr().out.splitlines()
                    if line.startswith("#"))
    assert "resistance = 1.0" in head and "required: inertia, torque_constant" in head
    for key, cls in PARTS.items():
        assert f"[{key}]" in head
        for f in fields(cls):
            if f.default is MISSING and f.default_factory is MISSING:
                assert f.name in head


def test_ctrl_c_is_one_line_exit_130(tmp_path, monkeypatch, capsys):
    from hdgym import sim

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(sim.Simulator, "trajectory", interrupted)
    out = tmp_path / "x.csv"
    assert main(["simulate", "--preset", "tuttle-joint1", "--command", "step:1",
                 "--duration", "1", "--out", str(out)]) == 130
    assert "interrupted" in _one_line(capsys) and list(tmp_path.iterdir()) == []


def test_ctrl_c_in_a_real_process(tmp_path):
    """SIGINT while a long simulation runs: exit 130, one line, no file."""
    import signal
    import time

    driver = ("import sys, hdgym.cli, hdgym.sim, hdgym.discrepancy.experiments\n"
              "print('ready', flush=True)\n"
              "sys.exit(hdgym.cli.main(sys.argv[1:]))\n")
    proc = subprocess.Popen([sys.executable, "-c", driver, "simulate", "--preset",
                             "tuttle-joint1", "--command", "random:1:20", "--duration", "300",
                             "--out", "x.csv"], cwd=tmp_path, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            # a user's shell delivers SIGINT; a test run started in the
                            # background inherits it ignored, and Python then keeps it so
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert proc.stdout.readline().strip() == "ready"
    time.sleep(1.5)  # into the run (which takes several seconds)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    lines = [ln for ln in err.strip().splitlines() if "compiling" not in ln]
    assert len(lines) == 1 and "interrupted" in lines[0], err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("action", [[[0.3]], "0.3", 0.3, ["0.3"], [0.1, 0.2]])
def test_env_step_rejects_what_box_1_cannot_hold(action):
    import gymnasium as gym
    import numpy as np

    import hdgym  # noqa: F401  (registers the ids)

    env = gym.make("HarmonicDriveJoint-v0").unwrapped
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(1,\)"):
        env.step(np.array(action) if isinstance(action, list) and action != ["0.3"] else action)
    env.step([0.3])  # a list of one number is castable
    env.step(np.array([0.3], dtype=np.float32))


def test_train_summary_names_files_relative(tmp_path, monkeypatch):
    """Reports name files relative to the checkout (issue 13 item 7), not by machine path."""
    from pathlib import Path

    from agents.common import DEFAULT_CONFIGS, load_config
    from agents.train import shown

    monkeypatch.chdir(tmp_path)
    src = load_config(DEFAULT_CONFIGS["ppo"])["source"]
    assert shown(src) == "agents/configs/resonance_ppo.toml" and not Path(shown(src)).is_absolute()
    assert shown(tmp_path / "runs" / "x" / "final.zip") == "runs/x/final.zip"


def test_bundled_spec_name_beside_a_folder_of_that_name(tmp_path, monkeypatch, capsys):
    """`hdgym sweep controllers` from the checkout root, where controllers/ is a folder."""
    (tmp_path / "controllers").mkdir()
    monkeypatch.chdir(tmp_path)
    results = _fake_repo(tmp_path)
    assert main(["sweep", "controllers", "--quick", "--out", str(results / "x")]) == 2
    assert "quick runs never write into results/" in capsys.readouterr().err  # spec was found


def test_results_goes_on_after_a_failed_fidelity_check(tmp_path, monkeypatch, capsys):
    """reproduce exits 1 when a check fails but has written its page: the build goes on."""
    import subprocess as sp

    ran = []

    def fake_run(cmd, *a, **k):
        ran.append(cmd)
        return sp.CompletedProcess(cmd, 1 if len(ran) == 1 else 0)

    monkeypatch.setattr(sp, "run", fake_run)
    assert main(["results", "--out", str(tmp_path / "r"), "--only", "fidelity", "numerics"]) == 0
    assert len(ran) == 2 and "fidelity: exit 1" in capsys.readouterr().err
