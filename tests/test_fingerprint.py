"""hdgym.reproduce.fingerprint: trajectory hashes that prove a change left the presets alone."""

from __future__ import annotations

import json

from hdgym.params import preset_names
from hdgym.reproduce import fingerprint


def test_fingerprints_are_repeatable_and_see_a_different_run(tmp_path):
    a = fingerprint.fingerprints(n_steps=20, seed=0)
    assert a == fingerprint.fingerprints(n_steps=20, seed=0)
    # every preset, through all three compiled steps, with its variants
    for name in preset_names():
        for how in ("kernel", "threaded", "lanes"):
            assert f"{name} all {how}" in a and f"{name} locked {how}" in a
    b = fingerprint.fingerprints(n_steps=20, seed=1)
    assert set(fingerprint.compare(b, a)) == set(a)  # another command moves every run
    before = tmp_path / "before.json"
    before.write_text(json.dumps(a))
    assert fingerprint.main(["--out", str(tmp_path / "same.json"), "--steps", "20",
                             "--compare", str(before)]) == 0
    before.write_text(json.dumps(dict(a, extra="0")))
    assert fingerprint.main(["--out", str(tmp_path / "diff.json"), "--steps", "20",
                             "--compare", str(before)]) == 1
