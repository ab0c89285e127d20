"""Trajectory fingerprints of every bundled preset: did a code change move any of them?

A physics option added behind a switch must leave every existing preset's
simulated trajectory unchanged, to the bit. This module runs each preset,
each preset with one effect switched off in turn, and each with the output
locked, through the compiled steps (the one-env kernel,
:func:`hdgym.physics.kernel.run_open_loop`, the threaded batch
:func:`hdgym.physics.kernel.step_parallel` and the SIMD lanes,
:class:`hdgym.physics.lanes.LaneBatch`) under a seeded random current, and
hashes the full state trajectory (every state column after every control
period, float64 bytes) with SHA-256.

Run it before and after a change on the same machine and compare::

    python -m hdgym.reproduce.fingerprint --out runs/fp-before.json
    (change)
    python -m hdgym.reproduce.fingerprint --out runs/fp-after.json --compare runs/fp-before.json

Bit-identity is only meaningful on one machine and one numba/LLVM build:
another CPU may fuse operations differently.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

from hdgym.effects import EFFECTS, flags_of
from hdgym.numerics import excitation
from hdgym.params import JointParams, atomic_write_text, preset, preset_names
from hdgym.physics import kernel
from hdgym.physics import layout as L
from hdgym.physics.lanes import LaneBatch


def _variants(p: JointParams) -> list[tuple[str, JointParams, bool]]:
    """(label, joint, locked output) for the preset, each effect off, and locked."""
    out = [("all", p, False), ("locked", p, True)]
    for e in EFFECTS:
        if e in p.effects:
            out.append((f"-{e}", p.without(e), False))
    return out


def _digest(a: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(a, dtype=np.float64).tobytes()).hexdigest()


def fingerprints(n_steps: int = 3000, seed: int = 0) -> dict[str, str]:
    """SHA-256 of every variant's full state trajectory, each compiled step, per preset."""
    out: dict[str, str] = {}
    for name in preset_names():
        base = preset(name)
        var = _variants(base)
        dt = base.integration.ctrl_dt
        n_sub = int(base.integration.n_substeps)
        u = excitation(base, n_steps, seed)
        rows = np.stack([L.pack(p) for _, p, _ in var])
        flags = np.array([flags_of(p.effects, locked_output=lk) for _, p, lk in var],
                         dtype=np.int64)
        # one env at a time through the kernel
        for k, (label, _, _) in enumerate(var):
            x = L.initial_state(rows[k][None, :], flags[k])[0]
            traj = np.empty((n_steps, L.N_STATE))
            kernel.run_open_loop(x, rows[k], u, np.zeros_like(u), dt / n_sub, n_sub,
                                 int(flags[k]), traj)
            out[f"{name} {label} kernel"] = _digest(traj)
        # all variants as one batch through the threaded kernel (what step_runs uses)
        xs = L.initial_state(rows, flags)
        bad = np.zeros(len(var), dtype=bool)
        zero = np.zeros(len(var))
        traj = np.empty((n_steps, len(var), L.N_STATE))
        for s in range(n_steps):
            kernel.step_parallel(xs, rows, np.full(len(var), u[s]), zero, dt / n_sub, n_sub,
                                 flags, bad)
            traj[s] = xs
        for k, (label, _, _) in enumerate(var):
            out[f"{name} {label} threaded"] = _digest(traj[:, k])
        # all variants side by side in SIMD lanes
        xs = L.initial_state(rows, flags)
        lanes = LaneBatch(xs, rows, flags, dt / n_sub)
        bad = np.zeros(len(var), dtype=bool)
        zero = np.zeros(len(var))
        traj = np.empty((n_steps, len(var), L.N_STATE))
        for s in range(n_steps):
            lanes.step(np.full(len(var), u[s]), zero, n_sub, xs, bad)
            traj[s] = xs
        for k, (label, _, _) in enumerate(var):
            out[f"{name} {label} lanes"] = _digest(traj[:, k])
    return out


def compare(now: dict[str, str], before: dict[str, str]) -> list[str]:
    """Keys whose hash differs, or that only one side has."""
    keys = sorted(set(now) | set(before))
    return [k for k in keys if now.get(k) != before.get(k)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m hdgym.reproduce.fingerprint",
                                 description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, required=True, help="JSON file to write")
    ap.add_argument("--compare", type=Path, help="an earlier JSON to compare with")
    ap.add_argument("--steps", type=int, default=3000, help="control periods per run")
    a = ap.parse_args(argv)
    now = fingerprints(a.steps)
    atomic_write_text(a.out, json.dumps(now, indent=1, sort_keys=True) + "\n")
    print(f"{len(now)} trajectories hashed -> {a.out}")
    if a.compare is None:
        return 0
    diff = compare(now, json.loads(a.compare.read_text()))
    for k in diff:
        print(f"DIFFERS: {k}")
    print(f"{len(now) - len(diff)} of {len(now)} identical to {a.compare}" if diff else
          f"all {len(now)} trajectories bit-identical to {a.compare}")
    return 1 if diff else 0


if __name__ == "__main__":
    sys.exit(main())
