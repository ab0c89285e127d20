"""The resonance benchmark end to end: fronts, the rules, the registered constants, the
policies, the page.

    python -m agents.benchmark --quick              # smoke run, writes runs/rl-quick/ only
    python -m agents.benchmark --out results/rl     # the committed page and policies

Steps, in order:

1. **Fronts** (:mod:`agents.front`): every classical family tuned on 64
   training episodes and measured on 200 held-out episodes, on each variant
   of :data:`agents.report.VARIANTS` (its config's env: ``resonance_ppo``,
   ``resonance_ppo_notorque``; the Long variant on its 6 s episodes, deadlines
   :data:`agents.front.LONG_DEADLINES`); written to ``--fronts-dir`` (default
   ``runs/rl``) as ``front_<variant id>.json``.
2. **Rules** (:mod:`agents.rules`): on the default variant's front the
   deadline, then the rating at that deadline; on the Long variant's front the
   long deadline at that rating.
3. **Check** the registered constants of ``hdgym/envs/resonance.py``
   (``DEADLINE``, ``LONG_DEADLINE``, ``GEAR_RATINGS``; ``LONG_DEADLINE`` and
   ``LONG_EPISODE`` also as registered in ``hdgym.envs``). If they differ from the
   rules the command stops (exit 3) and prints the lines to set; after the
   edit, ``--reuse-fronts`` continues from step 4 without recomputing the fronts
   (they do not depend on the constants). ``--quick`` only prints the
   comparison (its small fronts are not the rule's).
4. **KE feedforward** tuned on top of the best pick at the rating and deadline
   (on the long front: the long deadline), added to every front.
5. **Training** (:mod:`agents.train`) of both configs into
   ``runs/<config>-s0``; the final policies are copied to ``agents/policies/``
   (``--quick``: 4,096 agent steps into ``--fronts-dir``, nothing copied).
6. **The page** (:mod:`agents.report`): ``--out`` (default
   ``runs/rl-quick`` with ``--quick``; the committed page is ``--out
   results/rl``), comparing with the committed ``results/rl/evaluation.json``.

Measured on the shared 2-core machine (other jobs running): each 3 s front 1-2.5 min,
the long front about twice that, each training run 1.5-2.5 min (longer when the machine
is busy), the page 1-3.5 min; the whole command about 10-25 min.
``--quick`` takes well under a minute.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from agents import report
from agents.common import load_config
from agents.families import default_grids
from agents.front import DEADLINES, LONG_DEADLINES, add_ke, tune_and_test
from agents.rules import check_constants, registered, rules
from hdgym.files import check_out

CONFIGS = ("resonance_ppo", "resonance_ppo_notorque")
#: the variant whose front the deadline and rating rules read, and the long deadline's
MAIN, LONG = "HarmonicDriveResonance-v0", "HarmonicDriveResonanceLong-v0"
TRAIN_EPISODES, TEST_EPISODES, CHECK_EPISODES = 64, 200, 200
QUICK_EPISODES, QUICK_TIMESTEPS = 8, 4096
I_MAX = 6.0  # A, the preset's amplifier (the task's default)
ROOT = Path(__file__).resolve().parents[1]


def grids_for(variant: str, quick: bool) -> dict[str, list[dict[str, float]]]:
    """The families of a variant: without a torque sensor, damping from the encoders."""
    g = default_grids(I_MAX, quick)
    if variant.endswith("NoTorqueSensor-v0"):
        g = {("damp_enc" if k == "damp" else k): v for k, v in g.items() if k != "damp_full"}
    return g


def deadlines_for(variant: str) -> tuple[float, ...]:
    """The front's deadlines (s): the long variant's run to its 6 s episodes."""
    return LONG_DEADLINES if variant == LONG else DEADLINES


def log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def commit() -> str:
    """The checkout's commit (and ``+dirty`` with uncommitted changes), for provenance."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, text=True,
                              capture_output=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "hdgym"], cwd=ROOT,
                               text=True, capture_output=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("+dirty" if dirty else "")


def base_fronts(quick: bool, n_train: int, n_test: int, fronts_dir: Path, reuse: bool
                ) -> dict[str, dict[str, Any]]:
    """Step 1: the fronts of every variant without KE (read back with ``reuse``)."""
    train = list(range(report.TRAIN_SEED, report.TRAIN_SEED + n_train))
    test = list(range(report.TEST_SEED, report.TEST_SEED + n_test))
    out = {}
    for name in report.VARIANTS:
        path = fronts_dir / f"front_{name}.json"
        if reuse:
            if not path.is_file():
                raise ValueError(f"--reuse-fronts: {path} does not exist; run without it")
            f = json.loads(path.read_text())
            if f["train_seeds"] != [train[0], n_train] or f["test_seeds"] != [test[0], n_test]:
                raise ValueError(f"--reuse-fronts: {path} has other episodes "
                                 f"({f['train_seeds']}, {f['test_seeds']})")
            f["families"] = {k: v for k, v in f["families"].items() if "+" not in k}
            log(f"{name}: front read from {path} (computed at {f.get('commit', '?')})")
        else:
            t0 = time.perf_counter()
            cfg, _ = report.variant_config(name)
            f = tune_and_test(cfg, grids_for(name, quick), train, test,
                              deadlines=deadlines_for(name), log=log)
            f["variant"], f["config"], f["commit"] = name, report.VARIANTS[name][0], commit()
            f["wall_time_s"] = round(time.perf_counter() - t0, 1)
            log(f"{name}: front in {f['wall_time_s']:.0f} s")
            write_json(path, f)
        out[name] = f
    return out


def write_json(path: Path, data: Any) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(data, indent=1) + "\n")
    tmp.replace(path)


def train_policies(quick: bool, work: Path) -> Path:
    """Step 5: every config trained; returns the run folder of ``resonance_ppo``."""
    from agents.train import train

    runs = {}
    for name in CONFIGS:
        cfg = load_config(name)
        if quick:
            cfg["train"].update(total_timesteps=QUICK_TIMESTEPS, n_envs=8, eval_freq=0,
                                checkpoint_freq=0)
            out = work / f"train-{name}"
        else:
            out = ROOT / "runs" / f"{name}-s{cfg['train']['seed']}"
        if out.exists():
            shutil.rmtree(out)
        t = train(cfg, out, progress=False)
        log(f"{name}: trained {t['agent_steps']:,} agent steps in {t['wall_time_s'] / 60:.1f} "
            f"min -> {out / 'final.zip'}")
        runs[name] = out
        if not quick:
            shutil.copyfile(out / "final.zip", report.POLICIES / f"{name}.zip")
    return runs[CONFIGS[0]]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m agents.benchmark", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, help="page folder (committed: results/rl; default "
                    "runs/rl-quick with --quick, else runs/rl-page)")
    ap.add_argument("--quick", action="store_true", help="small grids, 8 episodes, 4,096 "
                    "training steps; writes runs/ only")
    ap.add_argument("--fronts-dir", type=Path, help="where the fronts go (default runs/rl; "
                    "with --quick runs/rl-quick, which also holds its training runs)")
    ap.add_argument("--reuse-fronts", action="store_true", help="read the fronts of an "
                    "earlier run from --fronts-dir instead of computing them")
    ap.add_argument("--skip-train", action="store_true", help="use the committed policies")
    ap.add_argument("--previous", type=Path, default=ROOT / "results" / "rl" / "evaluation.json",
                    help="evaluation.json of the page this run replaces (default: the "
                    "committed one); the page says what moved")
    args = ap.parse_args(argv)
    quick = args.quick
    fronts_dir = args.fronts_dir or ROOT / "runs" / ("rl-quick" if quick else "rl")
    out = args.out or (fronts_dir if quick else ROOT / "runs" / "rl-page")
    n_train, n_test = (QUICK_EPISODES, QUICK_EPISODES) if quick else (TRAIN_EPISODES,
                                                                      TEST_EPISODES)
    t_all = time.perf_counter()
    try:
        check_out(out, quick)
        fronts = base_fronts(quick, n_train, n_test, fronts_dir, args.reuse_fronts)
        try:
            ruled = rules(fronts[MAIN], fronts[LONG])
        except ValueError as exc:
            if not quick:
                raise
            log(f"quick: the small fronts give no rule values ({exc})")
            ruled = registered()
        log(f"rules: deadline {ruled['deadline']:g} s, rating {ruled['rating']:g} N m, long "
            f"deadline {ruled['long_deadline']} s; registered: {registered()}")
        edits = check_constants(ruled)
        if edits and not quick:
            print("agents.benchmark: the registered constants disagree with the rules on this "
                  "physics. Set in hdgym/envs/resonance.py:\n    " + "\n    ".join(edits) +
                  "\n(and the texts that state them), then rerun with --reuse-fronts.",
                  file=sys.stderr)
            return 3
        if edits:
            log("quick: the small fronts' rules would set " + ", ".join(edits) + " (not checked)")
        reg = registered()
        train = list(range(report.TRAIN_SEED, report.TRAIN_SEED + n_train))
        test = list(range(report.TEST_SEED, report.TEST_SEED + n_test))
        paths = []
        for name, f in fronts.items():
            d = reg["long_deadline"] if name == LONG else reg["deadline"]
            add_ke(report.variant_config(name)[0], f, reg["rating"], d, I_MAX, train, test,
                   quick, log)
            paths.append(fronts_dir / f"front_{name}_ke.json")
            write_json(paths[-1], f)
        t0 = time.perf_counter()
        run = None if args.skip_train else train_policies(quick, fronts_dir)
        t_train = None if args.skip_train else time.perf_counter() - t0
        rep = ["--out", str(out), "--episodes", str(n_test), "--train-episodes", str(n_train),
               "--check-episodes", str(QUICK_EPISODES if quick else CHECK_EPISODES),
               "--fronts", *map(str, paths),
               "--previous", str(args.previous),
               "--timing", json.dumps({"fronts_s": [f.get("wall_time_s") for f in
                                                    fronts.values()], "training_s": t_train})]
        if run is not None:
            rep += ["--run", str(run)]
        if quick:
            rep += ["--quick", "--policies", str(fronts_dir / "policies")]
            (fronts_dir / "policies").mkdir(parents=True, exist_ok=True)
            for name in CONFIGS:
                src = fronts_dir / f"train-{name}" / "final.zip"
                if src.is_file():
                    shutil.copyfile(src, fronts_dir / "policies" / f"{name}.zip")
        code = report.main(rep)
    except ValueError as exc:
        print(f"agents.benchmark: {exc}", file=sys.stderr)
        return 2
    log(f"benchmark done in {(time.perf_counter() - t_all) / 60:.1f} min")
    return code


if __name__ == "__main__":
    sys.exit(main())
