"""Sweeps: spec validation with file:line errors, resumable results, local and Ray backends."""

from __future__ import annotations

import csv
import importlib.util
import json
import textwrap
from pathlib import Path

import numpy as np
import pytest
from conftest import make_joint

from hdgym import params as P
from hdgym.sweep import load_spec, run_sweep, spec_names, spec_path
from hdgym.sweep.backends import run_job
from hdgym.sweep.job import draw_params
from hdgym.sweep.scenarios import (
    get_scenario,
    register,
    register_controller_scenario,
    scenario_names,
)
from hdgym.sweep.spec import find_line, parse_spec
from hdgym.sweep.store import ResultsStore, read_rows

SPEC = """\
# a small sweep: 2 drives x 2 grid points x 2 scenarios x 2 seeds = 16 jobs
[sweep]
name = "tiny"
presets = ["tuttle-joint1", "drive.toml"]
scenarios = ["current_steps", "locked_random"]
seeds = [0, 3]
quick = true

[spreads]
"compliance.stiffness" = 0.3
"friction.output" = 0.3

[grid]
"load.inertia" = [1.0, 1.5]

[scenario.current_steps]
fractions = [0.3]
quick_duration = 0.2

[scenario.locked_random]
quick_duration = 0.2
"""


@pytest.fixture
def spec_file(tmp_path: Path) -> Path:
    P.save(make_joint(), tmp_path / "drive.toml")
    f = tmp_path / "sweep.toml"
    f.write_text(SPEC)
    return f


def _rows(out: Path) -> dict[str, dict[str, str]]:
    header, rows = read_rows(out / "results.csv")
    assert len({r["job_id"] for r in rows}) == len(rows), "a job was written twice"
    return {r["job_id"]: {k: v for k, v in r.items() if k != "elapsed_s"} for r in rows}


# ----------------------------------------------------------------- the spec


def test_spec_expands_to_jobs_with_stable_ids(spec_file: Path) -> None:
    spec = load_spec(spec_file)
    jobs = spec.jobs()
    assert len(jobs) == 2 * 2 * 2 * 2
    ids = [j.job_id for j in jobs]
    assert len(set(ids)) == len(ids)
    assert ids == [j.job_id for j in load_spec(spec_file).jobs()]
    # the id is a hash of the inputs only: a new seed list keeps the old jobs' ids
    more = spec_file.with_name("more.toml")
    more.write_text(SPEC.replace("seeds = [0, 3]", "seeds = [0, 3, 5]"))
    assert set(ids) < {j.job_id for j in load_spec(more).jobs()}
    # quick from the caller overrides the spec and changes the ids
    assert not set(ids) & {j.job_id for j in load_spec(spec_file, quick=False).jobs()}


def test_randomized_drive_from_seed_and_inputs_only(spec_file: Path) -> None:
    jobs = load_spec(spec_file).jobs()
    j = jobs[0]
    base = j.base_params()
    p1, d1 = draw_params(base, j.grid, j.spreads, j.drive_rng())
    p2, d2 = draw_params(base, j.grid, j.spreads, j.drive_rng())
    assert p1 == p2 and d1 == d2
    k = base.compliance.stiffness
    assert 0.7 * k <= p1.compliance.stiffness <= 1.3 * k
    # a friction side scales as a whole: breakaway/coulomb ratio kept
    f0, f1 = base.friction.output, p1.friction.output
    factor = d1["friction.output"]
    assert 0.7 <= factor <= 1.3
    assert f1.coulomb == pytest.approx(f0.coulomb * factor)
    assert f1.breakaway == pytest.approx(f0.breakaway * factor)
    assert f1.stribeck_velocity == f0.stribeck_velocity
    # another scenario of the same drive and seed meets the same drive
    same = [o for o in jobs if o.preset == j.preset and o.seed == j.seed and o.grid == j.grid]
    assert len({draw_params(base, o.grid, o.spreads, o.drive_rng())[0] for o in same}) == 1
    other = next(o for o in jobs if o.preset == j.preset and o.seed != j.seed)
    assert draw_params(base, other.grid, other.spreads, other.drive_rng())[0] != p1


def test_run_job_is_deterministic(spec_file: Path) -> None:
    job = load_spec(spec_file).jobs()[1]
    a, b = run_job(job), run_job(job)
    assert a["status"] == "ok", a["error"]
    a.pop("elapsed_s")
    b.pop("elapsed_s")
    assert a == b
    assert a["hdgym_version"] and json.loads(a["inputs"])["seed"] == job.seed


BAD = [
    # (replace this, with this, message part, line of the key)
    ('presets = ["tuttle-joint1", "drive.toml"]', 'presets = ["tuttle-joint1", "nope"]',
     "unknown preset 'nope'", 4),
    ('"compliance.stiffness" = 0.3', '"compliance.stiffnes" = 0.3',
     "unknown parameter 'compliance.stiffnes'", 10),
    ('"load.inertia" = [1.0, 1.5]', '"load.inertia" = []', "is empty", 14),
    ('"load.inertia" = [1.0, 1.5]', '"load.inertai" = [1.0]', "unknown parameter", 14),
    ('"load.inertia" = [1.0, 1.5]', '"load.inertia" = [1.0, -2.0]', "load.inertia", 14),
    ('"friction.output" = 0.3', '"friction.output" = -0.1', ">= 0", 11),
    ('scenarios = ["current_steps", "locked_random"]', 'scenarios = ["current_steps", "warp"]',
     "unknown scenario 'warp'", 5),
    ('quick = true', 'quick = true\nworkers = 3', "unknown key 'workers' in [sweep]", 8),
    ('[grid]', '[gird]', "unknown key 'gird'", 13),
    ('fractions = [0.3]', 'fractoins = [0.3]', "unknown option 'fractoins'", 17),
    ('fractions = [0.3]', 'fractions = []', "non-empty list", 17),
    ('seeds = [0, 3]', 'seeds = [0, -3]', "seeds", 6),
    ('"friction.output" = 0.3', '"transmission.grounded" = 0.3', "not numeric", 11),
]


@pytest.mark.parametrize(("old", "new", "msg", "line"), BAD)
def test_bad_spec_names_file_and_line(tmp_path: Path, spec_file: Path, old: str, new: str,
                                      msg: str, line: int) -> None:
    text = SPEC.replace(old, new)
    assert text != SPEC
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    out = tmp_path / "out"
    with pytest.raises(ValueError) as info:
        run_sweep(bad, out, progress=False)
    text_msg = str(info.value)
    assert f"{bad}, line {line}:" in text_msg, text_msg
    assert msg in text_msg, text_msg
    assert not out.exists(), "a bad spec must fail before anything is written"


def test_find_line_handles_quoted_dotted_and_array_tables() -> None:
    text = textwrap.dedent("""\
        [sweep]
        seeds = 3
        [spreads]
        "compliance.stiffness" = 0.3
        friction.output = 0.2
        [spreads.load]
        inertia = 0.1
        [[controllers]]
        name = "a"
        [[controllers]]
        name = "b"
        """)
    assert find_line(text, "sweep", "seeds") == 2
    assert find_line(text, "spreads", "compliance.stiffness") == 4
    assert find_line(text, "spreads", "friction.output") == 5
    assert find_line(text, "spreads.load", "inertia") == 7
    assert find_line(text, "controllers", "name", 1) == 11
    with pytest.raises(ValueError, match=r"x\.toml, line 9: spread of 'load.inertia'"):
        parse_spec(text.replace("inertia = 0.1", "inertia = -0.1").replace(
            "seeds = 3", 'seeds = 3\npresets = ["tuttle-joint1"]\nscenarios = ["current_steps"]'
        ).replace("[[controllers]]\nname = \"a\"\n[[controllers]]\nname = \"b\"\n", ""),
            "x.toml")


def test_bundled_specs_are_valid() -> None:
    assert "open-loop" in spec_names()
    for name in spec_names():
        try:
            spec = load_spec(spec_path(name))
        except ValueError as exc:  # a spec whose scenarios' package is not importable here
            if "not importable" in str(exc) or "cannot import" in str(exc):
                continue
            raise
        assert spec.jobs()


# --------------------------------------------------------- results and resume


def test_store_drops_truncated_last_line_and_widens_header(tmp_path: Path) -> None:
    f = tmp_path / "results.csv"
    with ResultsStore(f, ["job_id", "a"]) as s:
        s.append({"job_id": "x1", "a": 1.5})
        s.append({"job_id": "x2", "a": 2.5, "b": "new, with comma"})
    with f.open("a") as fh:
        fh.write("x3,3.5,tr")  # killed mid-row
    with ResultsStore(f, ["job_id", "a"]) as s:
        assert s.done == {"x1", "x2"} and s.dropped == 1
        s.append({"job_id": "x4", "a": 4.0})
    header, rows = read_rows(f)
    assert header == ["job_id", "a", "b"]
    assert [r["job_id"] for r in rows] == ["x1", "x2", "x4"]
    assert rows[1]["b"] == "new, with comma" and rows[0]["b"] == ""
    assert float(rows[0]["a"]) == 1.5
    assert f.read_text().endswith("\n")


def test_local_sweep_writes_resumes_and_summarizes(tmp_path: Path, spec_file: Path) -> None:
    out = tmp_path / "run"
    res = run_sweep(spec_file, out, workers=2, progress=False)
    assert (res.total, res.skipped, res.ran, res.errors) == (16, 0, 16, 0)
    assert (out / "spec.toml").read_text() == SPEC
    full = _rows(out)
    assert len(full) == 16
    r = next(iter(full.values()))
    assert {"param:compliance.stiffness", "param:friction.output", "param:load.inertia"} <= set(r)
    steps = [r for r in full.values() if r["scenario"] == "current_steps"]
    assert all(float(r["speed_at_0.3Imax"]) > 0 for r in steps)
    locked = [r for r in full.values() if r["scenario"] == "locked_random"]
    assert all(float(r["torque_rms"]) > 0 for r in locked)
    assert all(r["speed_at_0.3Imax"] == "" for r in locked)

    # again: nothing to do
    res = run_sweep(spec_file, out, workers=2, progress=False, summarize=False)
    assert (res.skipped, res.ran) == (16, 0)

    # interrupted: keep 5 whole rows and half of the 6th, then resume
    lines = (out / "results.csv").read_text().splitlines(keepends=True)
    (out / "results.csv").write_text("".join(lines[:6]) + lines[6][: len(lines[6]) // 2])
    res = run_sweep(spec_file, out, workers=1, progress=False)
    assert (res.skipped, res.ran) == (5, 11)
    assert _rows(out) == full

    md = (out / "summary.md").read_text()
    assert "| tuttle-joint1 | – | torque_rms | 4 |" in md
    # it replaced the first run's page, with the same rows: it says nothing moved
    assert "## What moved since the previous run" in md
    assert " 0 of " in md.partition("## What moved")[2].splitlines()[2]
    assert "Regenerate: `hdgym sweep" in md
    assert (out / "summary.png").stat().st_size > 10_000


def test_sweep_shows_a_bar_and_a_closing_line(tmp_path: Path, spec_file: Path, capsys,
                                              monkeypatch) -> None:
    monkeypatch.delenv("TQDM_DISABLE", raising=False)
    res = run_sweep(spec_file, tmp_path / "run", workers=1, summarize=False)
    out, err = capsys.readouterr()
    name = "tiny"  # the spec's name
    assert f"sweep {name}" in err and "job" in err  # the bar, on stderr
    assert f"sweep {name}: 16 jobs, 0 already done, 16 run (0 errors)" in out
    assert res.ran == 16


def test_physics_fingerprint_follows_numbers_and_sources_not_notes(monkeypatch) -> None:
    from hdgym.sweep import job as J

    p = P.preset("tuttle-joint1")
    fp = J.physics_fingerprint(p)
    assert fp == J.physics_fingerprint(P.preset("tuttle-joint1"))
    assert J.physics_fingerprint(p.set("compliance.damping", 8.5)) != fp
    assert J.physics_fingerprint(p.without("hysteresis")) != fp
    notes = P.from_dict({**P.to_dict(p), "sources": {"motor.inertia": "another note"}})
    assert J.physics_fingerprint(notes) == fp
    # the physics sources are part of it
    monkeypatch.setattr(J, "_sources_digest", lambda: "edited")
    assert J.physics_fingerprint(p) != fp


def test_resume_recomputes_rows_made_on_other_physics(tmp_path: Path, spec_file: Path,
                                                       monkeypatch) -> None:
    """A changed preset number or physics source: the rows made before are moved to
    results.stale.csv and their jobs run again; the other preset's rows stay done."""
    from hdgym.sweep import job as J

    out = tmp_path / "run"
    res = run_sweep(spec_file, out, workers=1, progress=False, summarize=False)
    assert (res.ran, res.stale) == (16, 0)
    first = _rows(out)
    assert {r["physics"] for r in first.values() if r["preset"] == "tuttle-joint1"} == {
        J.physics_fingerprint(P.preset("tuttle-joint1"))}

    # the file drive's stiffness changes: its 8 rows are stale, tuttle-joint1's stay done
    P.save(make_joint().set("compliance.stiffness", 1.1 * make_joint().compliance.stiffness),
           spec_file.with_name("drive.toml"))
    res = run_sweep(spec_file, out, workers=1, progress=False)
    assert (res.skipped, res.ran, res.stale) == (8, 8, 8)
    now = _rows(out)
    assert len(now) == 16
    _, stale = read_rows(out / "results.stale.csv")
    assert {r["job_id"] for r in stale} == {k for k, r in first.items()
                                            if r["preset"] != "tuttle-joint1"}
    assert not set(now) & {r["job_id"] for r in stale}
    md = (out / "summary.md").read_text()
    assert "16 jobs (0 failed)" in md  # the summary counts only rows on today's physics

    # the physics code changes: every row is recomputed
    J._fingerprint_of.cache_clear()
    monkeypatch.setattr(J, "_sources_digest", lambda: "edited physics")
    res = run_sweep(spec_file, out, workers=1, progress=False, summarize=False)
    assert (res.skipped, res.ran, res.stale) == (0, 16, 16)
    J._fingerprint_of.cache_clear()

    # rows written before the physics column existed count as other physics
    monkeypatch.undo()
    res = run_sweep(spec_file, out, workers=1, progress=False, summarize=False)
    assert res.stale == 16
    header, rows = read_rows(out / "results.csv")
    with (out / "results.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, [c for c in header if c != "physics"], extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    res = run_sweep(spec_file, out, workers=1, progress=False, summarize=False)
    assert (res.stale, res.ran) == (16, 16)


def test_failing_job_is_a_row_not_a_crash(tmp_path: Path, spec_file: Path) -> None:
    @register("boom_for_test", options={})
    def boom(params, job):  # noqa: ANN001
        if job.seed == 3:
            raise RuntimeError("diverged\non purpose")
        return {"x": float(job.run_rng().uniform())}

    assert "boom_for_test" in scenario_names()
    f = tmp_path / "boom.toml"
    f.write_text(textwrap.dedent("""\
        [sweep]
        presets = ["tuttle-joint1"]
        scenarios = ["boom_for_test"]
        seeds = [0, 3]
        """))
    res = run_sweep(f, tmp_path / "out", workers=1, progress=False)
    assert (res.ran, res.errors) == (2, 1)
    rows = _rows(tmp_path / "out")
    err = next(r for r in rows.values() if r["status"] == "error")
    assert err["error"] == "RuntimeError: diverged on purpose" and err["x"] == ""
    assert "Failed jobs" in (tmp_path / "out" / "summary.md").read_text()


def test_importable_scenario_by_module_path(tmp_path: Path) -> None:
    f = tmp_path / "imp.toml"
    f.write_text(textwrap.dedent("""\
        [sweep]
        presets = ["tuttle-joint2"]
        scenarios = ["hdgym.sweep.scenarios:locked_random"]
        seeds = 1
        quick = true
        """))
    res = run_sweep(f, tmp_path / "out", workers=1, progress=False, summarize=False)
    assert res.errors == 0
    (row,) = _rows(tmp_path / "out").values()
    assert float(row["torque_rms"]) > 0


# ------------------------------------------------------------------ backends


@pytest.mark.skipif(importlib.util.find_spec("ray") is None,
                    reason='Ray is not installed (optional extra: pip install "hdgym[ray]")')
def test_ray_backend_gives_the_same_rows_as_the_local_pool(tmp_path: Path,
                                                           spec_file: Path) -> None:
    run_sweep(spec_file, tmp_path / "local", workers=2, progress=False, summarize=False)
    run_sweep(spec_file, tmp_path / "ray", backend="ray", workers=2, progress=False,
              summarize=False)
    local, ray_rows = _rows(tmp_path / "local"), _rows(tmp_path / "ray")
    assert len(local) == 16
    assert local == ray_rows


def test_results_csv_is_plain_csv(tmp_path: Path, spec_file: Path) -> None:
    out = tmp_path / "run"
    run_sweep(spec_file, out, workers=1, progress=False, summarize=False)
    with (out / "results.csv").open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 16
    vals = np.array([float(r["param:compliance.stiffness"]) for r in rows])
    assert np.all(np.isfinite(vals)) and len(set(vals)) > 1


# --------------------------------------------------------------- controllers

CTRL_SPEC = """\
[sweep]
presets = ["tuttle-joint2"]
scenarios = ["controllers:load_step"]
seeds = [0]
quick = true

[spreads]
"compliance.stiffness" = 0.3

[[controllers]]
name = "pid"
kind = "pid"

[[controllers]]
name = "dob"
kind = "pid+dob"

[[controllers]]
name = "ke"
kind = "pid+ke"
"""


@pytest.mark.skipif(importlib.util.find_spec("controllers") is None,
                    reason="the controllers package is not importable")
def test_controllers_meet_the_same_drive(tmp_path: Path) -> None:
    assert {"controllers:tracking", "controllers:load_step",
            "controllers:point_to_point"} <= set(scenario_names())
    f = tmp_path / "ctl.toml"
    f.write_text(CTRL_SPEC)
    res = run_sweep(f, tmp_path / "out", workers=1, progress=False, summarize=False)
    assert (res.ran, res.errors) == (3, 0)
    rows = {r["controller"]: r for r in _rows(tmp_path / "out").values()}
    assert set(rows) == {"pid", "dob", "ke"}
    assert len({r["param:compliance.stiffness"] for r in rows.values()}) == 1  # common numbers
    assert float(rows["pid"]["reduction_pct"]) == 0.0  # its own baseline
    assert 0 < float(rows["dob"]["peak_deviation_arcsec"]) < float(
        rows["pid"]["peak_deviation_arcsec"])
    assert rows["ke"]["peak_deviation_arcsec"] == ""  # KE feedforward sits the load step out
    bad = tmp_path / "bad.toml"
    bad.write_text(CTRL_SPEC.replace('kind = "pid+dob"', 'kind = "lqr"'))
    with pytest.raises(ValueError, match=r"bad\.toml, line 16: \[\[controllers\]\] 'dob': kind"):
        load_spec(bad)
    bad.write_text(CTRL_SPEC.replace('kind = "pid+dob"', 'kind = "pid+dob"\ndob_bandwidth_hz = -1'))
    with pytest.raises(ValueError, match=r"line 17: .*dob_bandwidth_hz must be a number > 0"):
        load_spec(bad)
    bad.write_text(CTRL_SPEC + '[scenario."controllers:load_step"]\nspeed = 1.0\n')
    with pytest.raises(ValueError, match=r"unknown option 'speed'"):
        load_spec(bad)


def test_controller_scenario_gets_the_arguments_it_accepts(tmp_path: Path) -> None:
    calls = []

    def tracking(params, controller, seed, quick, speed=1.0):  # noqa: ANN001
        calls.append((controller["name"], seed, quick, speed))
        return {"rms_error": 1e-3 * speed, "ok": 1}

    def check(config):  # noqa: ANN001
        if config.get("name") == "bad":
            raise ValueError("name must not be bad")

    register_controller_scenario("fake_controllers:tracking", tracking, check)
    assert "fake_controllers:tracking" in scenario_names()
    assert get_scenario("fake_controllers:tracking").options == {"speed": 1.0}
    f = tmp_path / "bm.toml"
    f.write_text(textwrap.dedent("""\
        [sweep]
        presets = ["tuttle-joint1"]
        scenarios = ["fake_controllers:tracking"]
        seeds = 2
        [scenario."fake_controllers:tracking"]
        speed = 2.0
        [[controllers]]
        name = "a"
        [[controllers]]
        name = "b"
        """))
    res = run_sweep(f, tmp_path / "out", workers=1, progress=False, summarize=False)
    assert (res.ran, res.errors) == (4, 0)
    assert sorted(c[0] for c in calls) == ["a", "a", "b", "b"]
    # the same seed gives both controllers the same run seed
    assert len({c[1] for c in calls}) == 2 and all(c[3] == 2.0 for c in calls)
    assert {r["rms_error"] for r in _rows(tmp_path / "out").values()} == {"0.002"}
    bad = tmp_path / "bad.toml"
    bad.write_text(f.read_text().replace('name = "b"', 'name = "bad"'))
    with pytest.raises(ValueError, match=r"bad\.toml, line 9: .*name must not be bad"):
        load_spec(bad)
