"""A sweep's job ids follow a scenario's task (code and config beyond the physics):
a resumed sweep reruns the jobs whose task changed (rl_train: the env's DEADLINE,
rating, reward; the agents code; the agent config)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

from hdgym import params as P
from hdgym.sweep import load_spec, run_sweep
from hdgym.sweep.store import read_rows


def _rows(out: Path) -> dict[str, dict[str, str]]:
    _, rows = read_rows(out / "results.csv")
    return {r["job_id"]: r for r in rows}


_TASK = {"digest": "task-a"}


def _task_scenario(params: P.JointParams, job) -> dict[str, float]:
    """Test scenario whose result depends on a task outside the physics."""
    return {"task_len": float(len(job.task))}


def test_resume_reruns_jobs_whose_task_changed(tmp_path: Path, monkeypatch) -> None:
    """A scenario that declares a task digest (rl_train: the env's task code and the
    agent config) gets it in its job ids; when it changes, the old rows go to
    results.stale.csv and the jobs run again; scenarios without one keep their ids."""
    from hdgym.sweep import scenarios as S

    monkeypatch.setitem(S._REGISTRY, "task_probe", S.Scenario(
        "task_probe", _task_scenario, task_digest=lambda slot: _TASK["digest"]))
    f = tmp_path / "task.toml"
    f.write_text(textwrap.dedent("""\
        [sweep]
        presets = ["tuttle-joint2"]
        scenarios = ["task_probe", "locked_random"]
        seeds = 2
        quick = true
        """))
    jobs = load_spec(f).jobs()
    assert {j.task for j in jobs if j.scenario == "task_probe"} == {"task-a"}
    plain = [j for j in jobs if j.scenario == "locked_random"]
    assert all(j.task == "" and "task" not in j.inputs() for j in plain)

    out = tmp_path / "out"
    res = run_sweep(f, out, workers=1, progress=False, summarize=False)
    assert (res.ran, res.stale) == (4, 0)
    res = run_sweep(f, out, workers=1, progress=False, summarize=False)
    assert (res.skipped, res.ran, res.stale) == (4, 0, 0)
    monkeypatch.setitem(_TASK, "digest", "task-b")
    assert {j.job_id for j in load_spec(f).jobs() if j.scenario == "locked_random"} == {
        j.job_id for j in plain}
    res = run_sweep(f, out, workers=1, progress=False, summarize=False)
    assert (res.skipped, res.ran, res.stale) == (2, 2, 2)
    _, stale = read_rows(out / "results.stale.csv")
    assert {r["scenario"] for r in stale} == {"task_probe"}
    assert len(_rows(out)) == 4


def test_rl_train_task_digest_follows_env_code_and_config(tmp_path: Path,
                                                           monkeypatch) -> None:
    sweep_mod = pytest.importorskip("agents.sweep")
    agent = {"name": "ppo", "config": "resonance_ppo"}
    d0 = sweep_mod.task_digest(agent)
    assert d0 == sweep_mod.task_digest(dict(agent)) and len(d0) == 16
    envs = tmp_path / "envs"
    envs.mkdir()
    (envs / "task.py").write_text("DEADLINE = 2.5\n")
    monkeypatch.setattr(sweep_mod, "_TASK_SOURCES", (envs,))
    d1 = sweep_mod.task_digest(agent)
    (envs / "task.py").write_text("DEADLINE = 2.0\n")
    assert sweep_mod.task_digest(agent) != d1
    cfg = tmp_path / "mine.toml"
    cfg.write_bytes(sweep_mod.config_path("resonance_ppo").read_bytes() + b"\n# edited\n")
    assert sweep_mod.task_digest({**agent, "config": str(cfg)}) != sweep_mod.task_digest(agent)
