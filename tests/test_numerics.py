"""Substep convergence table and soak runs (issue: reliability)."""

from __future__ import annotations

from hdgym import numerics
from hdgym.params import preset, preset_names


def test_convergence_rows_shrink_with_the_substep():
    for name in preset_names():
        rows = numerics.convergence(preset(name), duration=0.3, substeps=(1, 10, 40),
                                    reference=80)
        assert not any(r["diverged"] for r in rows), name
        assert rows[-1]["motor_angle"] < rows[0]["motor_angle"], name
        assert rows[-1]["torque_rms"] < 0.05, (name, rows[-1])


def test_soak_stays_bounded_without_memory_growth():
    r = numerics.soak(preset("tuttle-joint1"), n_steps=40_000, chunk=10_000)
    assert r["finite"] and r["steps"] == 40_000
    assert r["last"]["motor_velocity"] <= 1.5 * r["first"]["motor_velocity"]
    assert r["memory_end_mb"] - r["memory_start_mb"] < 50


def test_numerics_page(tmp_path):
    numerics.write_table(tmp_path / "numerics.md", quick=True)
    text = (tmp_path / "numerics.md").read_text()
    assert "hdgym numerics --quick" in text
    assert all(f"## {name}" in text for name in preset_names())
