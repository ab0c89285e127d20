"""Tune the classical families on training seeds; measure their success front.

    python -m agents.front --quick                       # a small grid, a few seconds
    python -m agents.front --out results/rl/front.json   # the committed front

Each family's grid (:func:`agents.families.default_grids`) runs as one
batch of the native vector env on ``--train`` training episodes (env
seeds ``--train-seed + k``) with no torque limit, so one run gives every
episode's time to target and peak |flexspline torque| over the whole
episode. Success at a torque cap ``R`` and deadline ``D`` is then
``time_to_target <= D and peak <= R``: exactly the task's success with
``torque_limit = R`` and ``deadline = D`` (a classical controller does not
know ``R``, so cutting the episode at ``R`` changes nothing before the cut).

For every family, cap and deadline the best grid point on the training
episodes is picked and re-run on ``--test`` held-out episodes (seeds
``--test-seed + k``); success is reported with a 95 % Wilson interval.
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from agents.common import env_kwargs, load_config
from agents.families import FamilyController, default_grids, family_of, ke_grid, label

#: N m, the torque caps of the front
CAPS = tuple(range(140, 401, 10))
#: s, the deadlines of the front (3 s episodes)
DEADLINES = (1.0, 1.25, 1.5, 2.0, 2.5, 3.0)
#: s, the deadlines of the long front (the long variant's 6 s episodes): from the default
#: deadline to half a second before the episode ends, as the default front's last
LONG_DEADLINES = (2.5, 3.0, 3.5, 4.0, 4.5, 5.0, 5.5)
NO_LIMIT = 1e9  # N m: the front runs uncut


def wilson(k: float, n: int, z: float = 1.96) -> tuple[float, float]:
    """95 % Wilson score interval of a success fraction ``k / n``."""
    if n <= 0:
        return (math.nan, math.nan)
    p = k / n
    den = 1.0 + z * z / n
    mid = (p + z * z / (2 * n)) / den
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return (max(0.0, mid - half), min(1.0, mid + half))


def uncut(cfg: Mapping[str, Any]) -> dict[str, Any]:
    """The config's env with no torque limit (the front is computed afterwards)."""
    out = copy.deepcopy(dict(cfg))
    out["env"]["kwargs"] = {**out["env"].get("kwargs", {}), "torque_limit": NO_LIMIT}
    return out


def run_batch(cfg: Mapping[str, Any], controller: Any, seeds: Sequence[int],
              repeat: int = 1) -> dict[str, np.ndarray]:
    """One episode per seed in one native batch; the controller acts every ``repeat``
    periods. Returns per-episode ``time_to_target`` (s, NaN if never), ``peak_torque``
    (N m) and ``terminated``."""
    e = cfg["env"]
    n = len(seeds)
    steps = int(e["max_episode_steps"])
    venv = gym.make_vec(e["id"], num_envs=n, vectorization_mode="vector_entry_point",
                        max_episode_steps=steps, **env_kwargs(cfg))
    obs, _ = venv.reset(seed=list(seeds))
    if hasattr(controller, "reset"):
        controller.reset(n)
    first = np.ones(n, dtype=bool)
    alive = np.ones(n, dtype=bool)
    ttt = np.full(n, np.nan)
    peak = np.zeros(n)
    terminated = np.zeros(n, dtype=bool)
    action = np.zeros((n, 1), dtype=np.float32)
    for k in range(steps):
        if k % repeat == 0:
            a, _ = controller.predict(obs, episode_start=first, deterministic=True)
            action = np.asarray(a, dtype=np.float32).reshape(n, 1)
            first[:] = False
        obs, _r, term, trunc, info = venv.step(action)
        ended = alive & (term | trunc)
        if ended.any():
            ttt[ended] = np.where(info["time_to_target"][ended] >= 0,
                                      info["time_to_target"][ended], np.nan)
            peak[ended] = info["peak_torque"][ended]
            terminated[ended] = term[ended]
            alive &= ~ended
            if not alive.any():
                break
    venv.close()
    return {"time_to_target": ttt, "peak_torque": peak, "terminated": terminated}


def success(ttt: np.ndarray, peak: np.ndarray, cap: float, deadline: float) -> np.ndarray:
    """Per-episode success at a torque cap (N m) and deadline (s)."""
    with np.errstate(invalid="ignore"):
        return (ttt <= deadline) & (peak <= cap)


def controller(cfg: Mapping[str, Any], name: str, params: Mapping[str, Any]) -> FamilyController:
    """A family controller on the config's env (nominal joint, scales)."""
    e = cfg["env"]
    probe = gym.make_vec(e["id"], num_envs=1, vectorization_mode="vector_entry_point",
                         **env_kwargs(cfg)).unwrapped
    b = probe.batch
    fam, source = family_of(name)
    if not b.sensor_params.torque_sensor and fam == "damp":
        source = "encoders"
    ctl = FamilyController(fam, params, b.params, b.speed_scale, b.ctrl_dt, source)
    probe.close()
    return ctl


def run_grid(cfg: Mapping[str, Any], name: str, points: Sequence[Mapping[str, float]],
             seeds: Sequence[int]) -> dict[str, np.ndarray]:
    """Every grid point on every seed, as one batch; arrays ``(len(points), len(seeds))``."""
    n = len(seeds)
    keys = list(points[0])
    params = {k: np.repeat([p[k] for p in points], n) for k in keys}
    ctl = controller(cfg, name, params)
    res = run_batch(uncut(cfg), ctl, list(seeds) * len(points))
    return {k: v.reshape(len(points), n) for k, v in res.items()}


def best_points(res: Mapping[str, np.ndarray], caps: Sequence[float],
                deadlines: Sequence[float]) -> np.ndarray:
    """Index of the best grid point per (deadline, cap), ``(len(deadlines), len(caps))``.

    Ties go to the smaller mean peak torque (the gentler controller)."""
    out = np.zeros((len(deadlines), len(caps)), dtype=int)
    mean_peak = res["peak_torque"].mean(axis=1)
    for i, d in enumerate(deadlines):
        for j, r in enumerate(caps):
            s = success(res["time_to_target"], res["peak_torque"], r, d).mean(axis=1)
            order = np.lexsort((mean_peak, -s))
            out[i, j] = order[0]
    return out


def tune_and_test(cfg: Mapping[str, Any], grids: Mapping[str, Sequence[Mapping[str, float]]],
                  train_seeds: Sequence[int], test_seeds: Sequence[int],
                  caps: Sequence[float] = CAPS, deadlines: Sequence[float] = DEADLINES,
                  log: Any = None) -> dict[str, Any]:
    """Tune each family on the training seeds, report the picks on the held-out seeds."""
    fams: dict[str, Any] = {}
    for name, points in grids.items():
        t0 = time.perf_counter()
        tr = run_grid(cfg, name, points, train_seeds)
        picks = best_points(tr, caps, deadlines)
        used = sorted(set(picks.ravel().tolist()))
        te = run_grid(cfg, name, [points[k] for k in used], test_seeds)
        pos = {k: i for i, k in enumerate(used)}
        n = len(test_seeds)
        front = []
        for i, d in enumerate(deadlines):
            row = []
            for j, r in enumerate(caps):
                k = int(picks[i, j])
                s_tr = success(tr["time_to_target"][k], tr["peak_torque"][k], r, d)
                s_te = success(te["time_to_target"][pos[k]], te["peak_torque"][pos[k]], r, d)
                lo, hi = wilson(float(s_te.sum()), n)
                row.append({"cap": r, "deadline": d, "point": points[k],
                            "train": float(s_tr.mean()), "test": float(s_te.mean()),
                            "ci": [lo, hi]})
            front.append(row)
        fams[name] = {"label": label(name), "grid_size": len(points),
                      "front": front}
        if log:
            log(f"{name}: {len(points)} points x {len(train_seeds)} training episodes, "
                f"{len(used)} picks x {n} held-out episodes, "
                f"{time.perf_counter() - t0:.0f} s")
    return {"caps": list(caps), "deadlines": list(deadlines), "train_seeds":
            [int(train_seeds[0]), len(train_seeds)], "test_seeds": [int(test_seeds[0]),
                                                                    len(test_seeds)],
            "families": fams}


def add_ke(cfg: Mapping[str, Any], front: dict[str, Any], cap: float, deadline: float,
           i_max: float, train_seeds: Sequence[int], test_seeds: Sequence[int],
           quick: bool = False, log: Any = None) -> str:
    """Tune KE feedforward on top of the best family's pick at (cap, deadline); adds the
    grid ``<family>+ke`` to ``front`` and returns its name."""
    fam, entry = best_classical(front, cap, deadline)
    name = f"{fam.partition('+')[0]}+ke"
    more = tune_and_test(cfg, {name: ke_grid(entry["point"], i_max, quick)}, train_seeds,
                         test_seeds, front["caps"], front["deadlines"], log)
    front["families"][name] = more["families"][name]
    return name


def best_classical(front: Mapping[str, Any], cap: float, deadline: float
                   ) -> tuple[str, dict[str, Any]]:
    """The family whose pick did best on the *training* episodes at (cap, deadline),
    and that pick's entry (its held-out success is then reported, not chosen on)."""
    i = front["deadlines"].index(deadline)
    j = front["caps"].index(cap)
    best = max(front["families"].items(), key=lambda kv: kv[1]["front"][i][j]["train"])
    return best[0], best[1]["front"][i][j]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m agents.front", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default="resonance_ppo", help="env config (name or path)")
    ap.add_argument("--train", type=int, default=128, help="training episodes")
    ap.add_argument("--test", type=int, default=256, help="held-out episodes")
    ap.add_argument("--train-seed", type=int, default=0)
    ap.add_argument("--test-seed", type=int, default=100_000)
    ap.add_argument("--families", nargs="+", help="grid names (default: all)")
    ap.add_argument("--ke", nargs=2, type=float, metavar=("CAP", "DEADLINE"),
                    help="also tune KE feedforward on the best pick at this cap (N m) and "
                    "deadline (s)")
    ap.add_argument("--quick", action="store_true", help="small grids, 16/32 episodes")
    ap.add_argument("--out", type=Path, help="write the front here (.json)")
    args = ap.parse_args(argv)
    try:
        cfg = load_config(args.config)
        if args.quick:
            args.train, args.test = min(args.train, 16), min(args.test, 32)
        probe = gym.make_vec(cfg["env"]["id"], num_envs=1,
                             vectorization_mode="vector_entry_point", **env_kwargs(cfg))
        i_max = probe.unwrapped.batch.current_limit
        torque_sensor = probe.unwrapped.batch.sensor_params.torque_sensor
        probe.close()
        grids = default_grids(i_max, args.quick)
        if not torque_sensor:  # no torque sensor: damping from the encoders' torsion
            grids = {("damp_enc" if k == "damp" else k): v for k, v in grids.items()
                     if k != "damp_full"}
        if args.families:
            unknown = set(args.families) - set(grids)
            if unknown:
                raise ValueError(f"--families: unknown {sorted(unknown)}; known {list(grids)}")
            grids = {k: grids[k] for k in args.families}
        if args.train < 1 or args.test < 1:
            raise ValueError("--train and --test must be >= 1")
        train_seeds = list(range(args.train_seed, args.train_seed + args.train))
        test_seeds = list(range(args.test_seed, args.test_seed + args.test))
        if set(train_seeds) & set(test_seeds):
            raise ValueError("training and held-out seeds overlap")
        front = tune_and_test(cfg, grids, train_seeds, test_seeds,
                              log=lambda m: print(m, file=sys.stderr))
        if args.ke:
            add_ke(cfg, front, args.ke[0], args.ke[1], i_max, train_seeds, test_seeds,
                   args.quick, log=lambda m: print(m, file=sys.stderr))
    except ValueError as exc:
        print(f"agents.front: {exc}", file=sys.stderr)
        return 2
    front["config"] = Path(cfg["source"]).stem
    for d_i, d in enumerate(front["deadlines"]):
        cells = []
        for cap in (160, 200, 240, 280):
            if cap in front["caps"]:
                name, e = best_classical(front, cap, d)
                cells.append(f"R={cap}: {100 * e['test']:.0f} % ({name})")
        print(f"D={d:.2f} s  " + "  ".join(cells))
        del d_i
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        tmp = args.out.with_suffix(".tmp")
        tmp.write_text(json.dumps(front, indent=1) + "\n")
        tmp.replace(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
