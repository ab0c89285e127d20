"""Record: CSV round trip and one clear RecordError per bad input.

Long because: one test per kind of bad record (missing column, NaN, time order,
units, metadata), each naming the file, row and column it expects.
"""

from __future__ import annotations

import math
import re
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hdgym.record import KNOWN_COLUMNS, Record, RecordError, read_record

HEADER = "time,current_command,motor_angle,output_angle"
META = "# ratio: 161\n# configuration: flexspline\n# locked_output: false\n# preset: test\n"


def rows(n: int = 6) -> list[str]:
    return [f"{k * 0.001!r},{0.5 * k},{1e-3 * k * k},{-2e-5 * k}" for k in range(n)]


def csv_text(n: int = 6, meta: str = META, header: str = HEADER) -> str:
    return meta + header + "\n" + "\n".join(rows(n)) + "\n"


def make_record(n: int = 50, seed: int = 0, **meta) -> Record:
    rng = np.random.default_rng(seed)
    cols = {
        "time": 0.25 + np.arange(n) * 1e-3,
        "current_command": rng.standard_normal(n),
        "motor_current": rng.standard_normal(n) * 1e-300,
        "motor_angle": np.cumsum(rng.standard_normal(n)) * 1e7,
        "output_angle": rng.standard_normal(n) / 3.0,
        "motor_velocity": rng.uniform(-1, 1, n),
        "output_torque": -rng.standard_normal(n),
        "load_torque": np.full(n, -0.0),
        "output_velocity": rng.standard_normal(n) * 1e-17,
    }
    base = {"ratio": 161.0, "configuration": "circular_spline", "locked_output": False,
            "preset": "tuttle-joint1", "source": "test, 'fixture' #1"}
    base.update(meta)
    return Record(cols, base)


def write(tmp_path: Path, text: str, name: str = "run.csv") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def error_of(tmp_path: Path, text: str, name: str = "run.csv") -> str:
    path = write(tmp_path, text, name)
    with pytest.raises(RecordError) as info:
        read_record(path)
    msg = str(info.value)
    assert msg.startswith(str(path) + ":"), msg
    assert "\n" not in msg
    return msg


# ------------------------------------------------------------------ good input


def test_round_trip_is_bit_exact(tmp_path: Path) -> None:
    rec = make_record()
    path = tmp_path / "out" / "run.csv"
    rec.to_csv(path)
    back = Record.from_csv(path)
    assert list(back.columns) == list(rec.columns)
    for name, values in rec.columns.items():
        assert back.columns[name].dtype == np.float64
        assert np.array_equal(back.columns[name], values)
        assert np.array_equal(np.signbit(back.columns[name]), np.signbit(values))
    assert back.meta == rec.meta
    assert back == rec
    assert back.locked_output is False and back.ratio == 161.0
    # written again, the file is identical
    again = tmp_path / "again.csv"
    back.to_csv(again)
    assert again.read_text() == path.read_text()
    assert not [p for p in path.parent.iterdir() if p.name != "run.csv"]  # no temp files left


def test_file_layout(tmp_path: Path) -> None:
    rec = make_record(n=3)
    path = tmp_path / "r.csv"
    rec.to_csv(path)
    lines = path.read_text().splitlines()
    assert lines[0] == "# ratio: 161.0"
    assert lines[5].startswith("time,current_command,")
    assert len(lines) == 5 + 1 + 3
    assert lines[6].split(",")[0] == "0.25"


def test_read_known_file(tmp_path: Path) -> None:
    rec = read_record(write(tmp_path, csv_text()))
    assert len(rec) == 6
    assert rec.dt == pytest.approx(1e-3)
    assert np.array_equal(rec.time, np.array([k * 0.001 for k in range(6)]))
    assert np.array_equal(rec.current_command, 0.5 * np.arange(6))
    assert rec.motor_current is None and rec.output_torque is None and rec.load_torque is None
    assert rec.has("output_angle") and not rec.has("motor_velocity")
    assert rec.meta == {"ratio": "161", "configuration": "flexspline", "locked_output": "false",
                        "preset": "test"}
    assert rec.ratio == 161.0
    with pytest.raises(RecordError, match="no column 'motor_velocity'"):
        rec.column("motor_velocity")
    with pytest.raises(ValueError):  # RecordError is a ValueError
        rec.column("nope")


def test_reordered_columns_extra_columns_crlf_and_blank_lines(tmp_path: Path) -> None:
    text = ("\ufeff# source: bench\r\n\r\n output_angle , reference, motor_angle,time\r\n"
            "0,1,2,0.0\r\n0,1,2.5,0.5\r\n0, 1 ,3,1.0\r\n\r\n\r\n")
    rec = read_record(write(tmp_path, text))
    assert rec.names == ("output_angle", "reference", "motor_angle", "time")
    assert np.array_equal(rec.motor_angle, [2, 2.5, 3])
    assert np.array_equal(rec.columns["reference"], [1, 1, 1])
    assert rec.dt == 0.5


def test_locked_output_needs_no_output_angle(tmp_path: Path) -> None:
    text = "# locked_output: true\ntime,motor_angle,output_torque\n0,0,1\n0.1,1,2\n"
    rec = read_record(write(tmp_path, text))
    assert rec.locked_output and rec.output_angle is None
    assert np.array_equal(rec.output_torque, [1, 2])


def test_jitter_within_tolerance_is_accepted(tmp_path: Path) -> None:
    t = np.arange(20) * 1e-3 + 1e6  # big offset: float rounding in the steps
    t[7] += 3e-6
    rec = Record({"time": t, "motor_angle": np.zeros(20), "output_angle": np.zeros(20)})
    rec.to_csv(tmp_path / "j.csv")
    assert read_record(tmp_path / "j.csv") == rec


def test_slice_and_immutability() -> None:
    rec = make_record(n=100)
    part = rec.slice(0.26, 0.27)
    assert len(part) == 10
    assert part.time[0] == rec.time[10] and part.meta == rec.meta
    assert len(rec.slice(t1=0.252)) == 2
    assert len(rec.slice(t0=0.3)) == len(rec) - 50
    with pytest.raises(RecordError, match="keeps 1 sample"):
        rec.slice(0.25, 0.2505)
    with pytest.raises(ValueError):
        rec.time[0] = 1.0
    with pytest.raises(AttributeError):
        rec.meta = {}  # type: ignore[misc]


def test_constructor_copies_and_converts() -> None:
    t = [0, 1, 2]
    a = np.array([1, 2, 3])
    rec = Record({"time": t, "motor_angle": a, "output_angle": a}, {"locked_output": True})
    a[0] = 99
    assert rec.motor_angle[0] == 1 and rec.motor_angle.dtype == np.float64
    assert rec.meta["locked_output"] == "true"


@pytest.mark.parametrize("cols, meta, match", [
    ({"time": [0, 1], "motor_angle": [0, 1]}, {}, "missing required column 'output_angle'"),
    ({"time": [0, 1], "motor_angle": [0, 1, 2], "output_angle": [0, 1]}, {}, "has 3 samples"),
    ({"time": [0, 1], "motor_angle": [0, np.nan], "output_angle": [0, 1]}, {},
     r"sample 1, column 'motor_angle': nan is not finite"),
    ({"time": [0, 1], "motor_angle": ["a", "b"], "output_angle": [0, 1]}, {}, "not numeric"),
    ({"time": [0, 1], "motor_angle": [1j, 1], "output_angle": [0, 1]}, {}, "not numeric"),
    ({"time": [0, 0], "motor_angle": [0, 1], "output_angle": [0, 1]}, {},
     r"sample 1, column 'time': time 0.0 repeats 0.0 \(sample 0\)"),
    ({"time": [0], "motor_angle": [0], "output_angle": [0]}, {}, "at least 2"),
    ({"time": [[0, 1]], "motor_angle": [0], "output_angle": [0]}, {}, "one-dimensional"),
    ({"time": [0, 1], "motor_angle": [0, 1], "output_angle": [0, 1], "a,b": [0, 1]}, {},
     "cannot be written"),
    ({"time": [0, 1], "motor_angle": [0, 1], "output_angle": [0, 1]}, {"ratio": 0.5},
     "'ratio' must be a number > 1"),
    ({"time": [0, 1], "motor_angle": [0, 1], "output_angle": [0, 1]}, {"source": "a\nb"},
     "must be one line"),
    ({"time": [0, 1], "motor_angle": [0, 1], "output_angle": [0, 1]}, {"my key": "x"},
     "malformed"),
])
def test_constructor_rejects(cols, meta, match) -> None:
    with pytest.raises(RecordError, match=match):
        Record(cols, meta, source="mem")


# ------------------------------------------------------------------ bad files


def test_missing_and_unreadable_file(tmp_path: Path) -> None:
    with pytest.raises(RecordError, match=r"nope\.csv: cannot read: no such file"):
        read_record(tmp_path / "nope.csv")
    with pytest.raises(RecordError, match="is a directory"):
        read_record(tmp_path)
    bad = tmp_path / "latin1.csv"
    bad.write_bytes(b"time,motor_angle,output_angle\n0,0,0\n1,\xe9,0\n")
    with pytest.raises(RecordError, match=r"latin1\.csv: row 3: not UTF-8"):
        read_record(bad)


@pytest.mark.parametrize("text", ["", "\n\n  \n"])
def test_empty_file(tmp_path: Path, text: str) -> None:
    assert "file is empty" in error_of(tmp_path, text)


def test_no_header(tmp_path: Path) -> None:
    msg = error_of(tmp_path, META + "\n".join(rows()) + "\n")
    assert "row 5 (header): no header row" in msg
    assert "no header row" in error_of(tmp_path, META)


@pytest.mark.parametrize("header, match", [
    ("time,motor_angle,,output_angle", r"row 5 \(header\): column 3 has an empty name"),
    ("time,motor_angle,output_angle,", r"row 5 \(header\): column 4 has an empty name"),
    ("time,motor_angle,time,output_angle", r"row 5 \(header\), column 'time': duplicate"),
])
def test_bad_header(tmp_path: Path, header: str, match: str) -> None:
    text = META + header + "\n" + "\n".join(r + ",0" for r in ["0,0,0", "1,0,0"]) + "\n"
    msg = error_of(tmp_path, text)
    assert re.search(match, msg), msg


def test_missing_required_column(tmp_path: Path) -> None:
    msg = error_of(tmp_path, csv_text(header="time,current_command,motor_angle,out_angle"))
    assert "row 5 (header): missing required column 'output_angle'" in msg
    assert "time, current_command, motor_angle, out_angle" in msg  # what the file has
    assert "locked_output" in msg
    msg = error_of(tmp_path, "time,output_angle\n0,0\n1,1\n")
    assert "missing required column 'motor_angle'" in msg


def test_renamed_column_hints_expected_names(tmp_path: Path) -> None:
    msg = error_of(tmp_path, csv_text(header="time,current_command,motor_angle_deg,output_angle"))
    assert "missing required column 'motor_angle'" in msg
    assert "'motor_angle_deg' is not 'motor_angle'" in msg
    for name in KNOWN_COLUMNS:
        assert name in msg


@pytest.mark.parametrize("cut, match", [
    ("0.003,1.5,9e-06", r"row 8, column 'output_angle': missing value; the row has 3 fields"),
    ("0.003,1.5,9e-06,1,2", r"row 8: 5 fields but the header has 4 \(extra value '2'"),
    ("0.003", r"row 8, column 'current_command': missing value"),
])
def test_truncated_or_long_rows(tmp_path: Path, cut: str, match: str) -> None:
    lines = csv_text().splitlines()
    lines[7] = cut
    msg = error_of(tmp_path, "\n".join(lines) + "\n")
    assert re.search(match, msg), msg


def test_file_cut_mid_row(tmp_path: Path) -> None:
    text = csv_text()
    cut = text[: text.rindex(",")]  # last row loses its last field
    assert "row 11, column 'output_angle': missing value" in error_of(tmp_path, cut)


@pytest.mark.parametrize("value, shown", [("abc", "'abc'"), ("", "empty field"),
                                          ("1_000", "'1_000'"), ('"1.0"', "'\"1.0\"'"),
                                          ("1.5.2", "'1.5.2'"), ("０", "'０'")])
def test_text_in_numeric_column(tmp_path: Path, value: str, shown: str) -> None:
    lines = csv_text().splitlines()
    fields = lines[8].split(",")
    fields[2] = value
    lines[8] = ",".join(fields)
    msg = error_of(tmp_path, "\n".join(lines))
    assert msg.endswith(f"row 9, column 'motor_angle': {shown} is not a number"), msg


def test_text_in_extra_column(tmp_path: Path) -> None:
    text = "time,motor_angle,output_angle,note\n0,0,0,1\n1,1,1,ok\n"
    assert "row 3, column 'note': 'ok' is not a number" in error_of(tmp_path, text)


@pytest.mark.parametrize("value", ["nan", "NaN", "inf", "-Infinity", "1e999"])
def test_nan_and_inf(tmp_path: Path, value: str) -> None:
    lines = csv_text().splitlines()
    fields = lines[6].split(",")
    fields[3] = value
    lines[6] = ",".join(fields)
    msg = error_of(tmp_path, "\n".join(lines))
    assert f"row 7, column 'output_angle': '{value}' is not finite" in msg


def test_time_repeated_or_backwards(tmp_path: Path) -> None:
    lines = csv_text().splitlines()
    lines[7], lines[8] = lines[8], lines[7]
    msg = error_of(tmp_path, "\n".join(lines))
    assert "row 9, column 'time': time 0.002 goes backwards from 0.003 (row 8)" in msg
    lines = csv_text().splitlines()
    lines[8] = lines[7]
    msg = error_of(tmp_path, "\n".join(lines))
    assert "row 9, column 'time': time 0.002 repeats 0.002 (row 8)" in msg
    assert "strictly increasing" in msg


def test_non_uniform_time_step(tmp_path: Path) -> None:
    t = [0.0, 0.001, 0.002, 0.003, 0.005, 0.006, 0.007]  # one sample dropped
    body = "\n".join(f"{x!r},0,0" for x in t)
    msg = error_of(tmp_path, "time,motor_angle,output_angle\n" + body)
    assert "row 6, column 'time': time step" in msg and "uniform" in msg
    t = [0.0, 0.001, 0.002, 0.00302, 0.004, 0.005]  # 2 % jitter on one sample
    body = "\n".join(f"{x!r},0,0" for x in t)
    assert "row 5, column 'time'" in error_of(tmp_path, "time,motor_angle,output_angle\n" + body)


@pytest.mark.parametrize("n", [0, 1])
def test_fewer_than_two_rows(tmp_path: Path, n: int) -> None:
    assert "at least 2" in error_of(tmp_path, csv_text(n=n))


@pytest.mark.parametrize("line, match", [
    ("# ratio 161", r"row 1: malformed metadata line '# ratio 161'"),
    ("#", r"row 1: malformed metadata line"),
    ("# recorded on bench: 3", r"row 1: malformed metadata line .* not a single word"),
    ("# ratio: abc", r"row 1: metadata 'ratio' must be a number > 1"),
    ("# ratio: 0.5", r"row 1: metadata 'ratio' must be a number > 1"),
    ("# ratio: nan", r"row 1: metadata 'ratio' must be a number > 1"),
    ("# locked_output: maybe", r"row 1: metadata 'locked_output' must be true or false"),
    ("# configuration: wave_generator", r"row 1: metadata 'configuration' must name the grounded"),
    ("# units: deg", r"row 1: metadata 'units' must be SI"),
    ("# preset: a\n# preset: b", r"row 2: metadata key 'preset' appears twice"),
])
def test_bad_metadata(tmp_path: Path, line: str, match: str) -> None:
    msg = error_of(tmp_path, line + "\n" + csv_text(meta=""))
    assert re.search(match, msg), msg


def test_comment_and_blank_line_inside_data(tmp_path: Path) -> None:
    lines = csv_text().splitlines()
    msg = error_of(tmp_path, "\n".join(lines[:7] + ["# ratio: 100"] + lines[7:]))
    assert "row 8: '#' line after the header" in msg
    msg = error_of(tmp_path, "\n".join(lines[:7] + [""] + lines[7:]))
    assert "row 8: empty line inside the data" in msg


def test_huge_file_error_names_the_row(tmp_path: Path) -> None:
    n = 20_000
    body = "\n".join(f"{k},{k},{k}" for k in range(n))
    text = "time,motor_angle,output_angle\n" + body + "\n20000,x,1\n"
    assert f"row {n + 2}, column 'motor_angle': 'x'" in error_of(tmp_path, text)
    rec = read_record(write(tmp_path, "time,motor_angle,output_angle\n" + body))
    assert len(rec) == n and rec.motor_angle[-1] == n - 1


# ------------------------------------------------------------------ writing


def test_write_into_a_file_as_directory_leaves_nothing(tmp_path: Path) -> None:
    blocker = tmp_path / "blocker"
    blocker.write_text("x")
    with pytest.raises(RecordError, match="cannot write"):
        make_record().to_csv(blocker / "run.csv")
    assert blocker.read_text() == "x"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["blocker"]


def test_invalid_record_is_not_written(tmp_path: Path) -> None:
    rec = make_record()
    bad = rec.motor_angle.copy()
    bad[3] = np.nan
    rec.columns["motor_angle"] = bad  # columns is a plain dict: mutation is possible
    target = tmp_path / "run.csv"
    with pytest.raises(RecordError, match="sample 3, column 'motor_angle': nan is not finite"):
        rec.to_csv(target)
    assert not target.exists() and not list(tmp_path.iterdir())


def test_failed_write_keeps_the_old_file(tmp_path: Path) -> None:
    target = tmp_path / "run.csv"
    target.write_text("old")
    rec = make_record()
    rec.meta["ratio"] = "0.1"
    with pytest.raises(RecordError, match="'ratio' must be a number > 1"):
        rec.to_csv(target)
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["run.csv"]


# ------------------------------------------------------------------ fuzzing


def _reference_parse(text: str) -> tuple[list[str], list[list[float]]]:
    """A deliberately simple independent reading of the format."""
    text = text.replace("\r\n", "\n").replace("\r", "\n").removeprefix("\ufeff")
    lines = [ln for ln in text.split("\n") if ln.strip()]
    while lines and lines[0].strip().startswith("#"):
        lines.pop(0)
    names = [n.strip() for n in lines[0].split(",")]
    names = [n[1:-1].strip() if len(n) >= 2 and n[0] == n[-1] == '"' else n for n in names]
    data = []
    for line in lines[1:]:
        fields = line.split(",")
        assert len(fields) == len(names)
        assert all("_" not in f and f.isascii() for f in fields)
        data.append([float(f) for f in fields])
    return names, data


_MUTATION = st.one_of(
    st.tuples(st.just("truncate"), st.floats(0, 1)),
    st.tuples(st.just("replace"), st.integers(0, 10**6), st.text(max_size=8)),
    st.tuples(st.just("swap"), st.integers(0, 10**6), st.integers(0, 10**6)),
    st.tuples(st.just("delete_column"), st.integers(0, 10**6)),
    st.tuples(st.just("nan"), st.integers(0, 10**6), st.sampled_from(["nan", "inf", "-inf"])),
    st.tuples(st.just("bytes"), st.floats(0, 1), st.binary(min_size=1, max_size=3)),
)


def _mutate(text: str, op: tuple) -> str:
    meta_lines = [ln for ln in text.split("\n") if ln.startswith("#")]
    rest = [ln for ln in text.split("\n") if not ln.startswith("#")]
    if not rest or not rest[0]:
        return text
    header, body = rest[0], [ln for ln in rest[1:] if ln]
    kind = op[0]
    if kind == "truncate":
        return text[: int(op[1] * len(text))]
    if kind == "swap" and body:
        i, j = op[1] % len(body), op[2] % len(body)
        body[i], body[j] = body[j], body[i]
    elif kind in ("replace", "nan") and body:
        i = op[1] % (len(body) * 4)
        fields = body[i // 4].split(",")
        if i % 4 < len(fields):
            fields[i % 4] = op[2]
        body[i // 4] = ",".join(fields)
    elif kind == "delete_column":
        k = op[1] % 4
        header = ",".join(f for n, f in enumerate(header.split(",")) if n != k)
        body = [",".join(f for n, f in enumerate(ln.split(",")) if n != k) for ln in body]
    return "\n".join(meta_lines + [header] + body) + "\n"


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(ops=st.lists(_MUTATION, min_size=1, max_size=3))
def test_fuzzed_csv_reads_consistently_or_fails_cleanly(ops: list) -> None:
    text = csv_text(n=8)
    raw = None
    for op in ops:
        if op[0] == "bytes":
            data = (raw if raw is not None else text.encode())
            at = int(op[1] * len(data))
            raw = data[:at] + op[2] + data[at:]
        elif raw is None:
            text = _mutate(text, op)
    payload = raw if raw is not None else text.encode()
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "fuzz.csv"
        path.write_bytes(payload)
        try:
            rec = read_record(path)
        except RecordError as exc:
            assert str(exc).startswith(f"{path}: ")
            return
    # it read: the data must be finite, valid and exactly what the text says
    names, data = _reference_parse(payload.decode("utf-8-sig"))
    assert list(rec.names) == names
    table = np.array(data, dtype=float)
    assert table.shape == (len(rec), len(names))
    for j, name in enumerate(names):
        assert np.array_equal(rec.columns[name], table[:, j])
        assert np.isfinite(rec.columns[name]).all()
    assert (np.diff(rec.time) > 0).all() and len(rec) >= 2
    assert math.isfinite(rec.dt) and rec.dt > 0


def test_command_file_needs_only_time_and_command(tmp_path):
    path = tmp_path / "cmd.csv"
    path.write_text("# kind: command\ntime,current_command\n0,1.0\n0.001,1.5\n0.002,2.0\n")
    rec = read_record(path)
    assert rec.meta["kind"] == "command" and not rec.has("motor_angle")
    with pytest.raises(RecordError, match="motor_angle"):
        _ = rec.motor_angle
    path.write_text("# kind: command\ntime,motor_angle\n0,1.0\n0.001,1.5\n")
    with pytest.raises(RecordError, match="current_command"):
        read_record(path)
    path.write_text("# kind: protocol\ntime,current_command\n0,1.0\n0.001,1.5\n")
    with pytest.raises(RecordError, match="'kind'"):
        read_record(path)


def test_command_file_drives_the_simulator(tmp_path):
    from hdgym.params import preset
    from hdgym.sim import Simulator

    path = tmp_path / "cmd.csv"
    t = np.arange(300) * 1e-3
    Record({"time": t, "current_command": np.full(300, 2.0)}, {"kind": "command"}).to_csv(path)
    rec = Simulator(preset("tuttle-joint1")).run(str(path), 0.3)
    assert np.all(rec.current_command == 2.0)


# --- issue 13 items 5, 6 ----------------------------------------------------------------------

def test_missing_output_angle_does_not_suggest_motor_angle(tmp_path):
    f = tmp_path / "r.csv"
    f.write_text("time,current_command,motor_angle\n0,0,0\n0.001,0,0\n")
    with pytest.raises(RecordError) as exc:
        read_record(f)
    msg = str(exc.value)
    assert "missing required column 'output_angle'" in msg
    assert "rename" not in msg and "'motor_angle' is not" not in msg


def test_misspelt_column_still_gets_a_hint(tmp_path):
    f = tmp_path / "r.csv"
    f.write_text("time,motor_angle,output_angel\n0,0,0\n0.001,0,0\n")
    with pytest.raises(RecordError, match="'output_angel' is not 'output_angle'"):
        read_record(f)


def test_two_column_command_file_drives_the_simulator(tmp_path):
    from hdgym.cli import main

    cmd = tmp_path / "cmd.csv"
    cmd.write_text("time,current_command\n0,0.5\n0.05,1.0\n0.1,1.0\n")
    out = tmp_path / "run.csv"
    assert main(["simulate", "--preset", "tuttle-joint1", "--command", str(cmd),
                 "--duration", "0.1", "--out", str(out)]) == 0
    u = read_record(out).current_command
    assert u[0] == 0.5 and u[-1] == 1.0
    with pytest.raises(RecordError, match="missing required column 'motor_angle'"):
        read_record(cmd)  # as a record it is still incomplete
