"""The ``hdgym`` command.

Exit code 0 on success, 2 on bad input with one line on stderr naming what
is wrong, 1 when a simulation fails (e.g. diverges).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from hdgym.effects import EFFECTS


def _params(args: argparse.Namespace):
    from hdgym import params

    if getattr(args, "params", None):
        p = params.load(args.params)
    else:
        p = params.preset(args.preset)
    without = getattr(args, "without", None) or []
    return p.without(*without) if without else p


def _add_joint(sp: argparse.ArgumentParser, required: bool = True) -> None:
    g = sp.add_mutually_exclusive_group(required=required)
    g.add_argument("--preset", help="bundled preset name (see `hdgym params --list`)")
    g.add_argument("--params", help="parameter TOML file")
    sp.add_argument("--without", nargs="*", default=[], metavar="EFFECT",
                    help=f"effects to switch off: {', '.join(EFFECTS)}")


def cmd_simulate(args: argparse.Namespace) -> int:
    from hdgym.sim import Simulator

    sim = Simulator(_params(args), locked_output=args.locked_output,
                    sensors=not args.true_states)
    cmd = args.command
    rec = sim.run(cmd, args.duration, seed=args.seed, load_torque=args.load_torque)
    rec.to_csv(args.out)
    print(f"wrote {args.out}: {len(rec)} rows, {args.duration} s")
    return 0


def cmd_params(args: argparse.Namespace) -> int:
    from hdgym import params

    if args.list:
        for name in params.preset_names():
            print(name)
        return 0
    if not args.preset or not args.out:
        raise ValueError("params: give --preset NAME --out FILE.toml (or --list)")
    params.save(params.preset(args.preset), args.out)
    print(f"wrote {args.out}")
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    from hdgym import bench

    sections = bench.run(quick=args.quick, out=Path(args.out), soak=args.soak)
    for title, rows in sections.items():
        print(title)
        for r in rows:
            ratio = f"  ratio {r['ratio']:.3g}" if r.get("ratio") is not None else ""
            print(f"  {r['name']}: {r['value']:,.0f} {r.get('unit', '')}{ratio}")
    print(f"wrote {args.out}")
    return 0


def cmd_numerics(args: argparse.Namespace) -> int:
    from hdgym import numerics

    numerics.write_table(Path(args.out), quick=args.quick)
    print(f"wrote {args.out}")
    return 0


def cmd_reproduce(args: argparse.Namespace) -> int:
    from hdgym import reproduce

    if args.what != "tuttle":
        raise ValueError(f"reproduce: unknown study {args.what!r}; known: tuttle")
    ok = reproduce.tuttle(Path(args.out), quick=args.quick)
    print(f"wrote {args.out}/fidelity.md")
    return 0 if ok else 1


def cmd_experiment(args: argparse.Namespace) -> int:
    from hdgym.discrepancy import experiments

    p = _params(args)
    rec = experiments.generate(args.name, p, duration=args.duration, seed=args.seed)
    rec.to_csv(args.out)
    print(f"wrote {args.out}: {len(rec)} rows of protocol {args.name!r}")
    return 0


def cmd_diagnose(args: argparse.Namespace) -> int:
    from hdgym.discrepancy.files import diagnose_files

    report = diagnose_files(args.record, _params(args), out=Path(args.out),
                            validate=args.validate)
    found = ", ".join(report["missing_effects"]) or "none"
    print(f"missing effects: {found}; NMSE {report['nmse_before']:.3g} % -> "
          f"{report['nmse_after']:.3g} %; wrote {args.out}/report.md")
    return 0


def cmd_controllers(args: argparse.Namespace) -> int:
    from controllers import benchmark

    benchmark.run(Path(args.out), quick=args.quick)
    print(f"wrote {args.out}")
    return 0


def cmd_sweep(args: argparse.Namespace) -> int:
    from hdgym.sweep import run_sweep

    run_sweep(Path(args.spec), Path(args.out), backend=args.backend, address=args.address,
              workers=args.workers, quick=True if args.quick else None)
    return 0


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="hdgym", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)

    sp = sub.add_parser("simulate", help="run a command signal and write a record CSV")
    _add_joint(sp)
    sp.add_argument("--locked-output", action="store_true")
    sp.add_argument("--command", required=True,
                    help="step:A | ramp:A0:A1 | sine:A:HZ | chirp:A:HZ0:HZ1 | random:A:CUTOFF_HZ "
                         "| FILE.csv")
    sp.add_argument("--duration", type=float, required=True, help="s")
    sp.add_argument("--load-torque", type=float, default=None, help="external load, N m")
    sp.add_argument("--seed", type=int, default=0)
    sp.add_argument("--true-states", action="store_true",
                    help="record true states instead of what the sensors measure")
    sp.add_argument("--out", required=True)
    sp.set_defaults(fn=cmd_simulate)

    sp = sub.add_parser("params", help="write a preset to a TOML file to edit")
    sp.add_argument("--preset")
    sp.add_argument("--out")
    sp.add_argument("--list", action="store_true", help="list the presets")
    sp.set_defaults(fn=cmd_params)

    sp = sub.add_parser("diagnose", help="find and name the effects a model misses")
    sp.add_argument("record")
    _add_joint(sp)
    sp.add_argument("--validate", help="validation record CSV")
    sp.add_argument("--out", required=True)
    sp.set_defaults(fn=cmd_diagnose)

    sp = sub.add_parser("experiment", help="identification protocols as command signals")
    sp.add_argument("name")
    _add_joint(sp)
    sp.add_argument("--duration", type=float, default=None)
    sp.add_argument("--seed", type=int, default=0)
    sp.add_argument("--out", required=True)
    sp.set_defaults(fn=cmd_experiment)

    sp = sub.add_parser("bench", help="benchmarks → results/bench.md")
    sp.add_argument("--quick", action="store_true")
    sp.add_argument("--soak", action="store_true",
                    help="add a million-step soak run per preset (long; not in CI)")
    sp.add_argument("--out", default="results/bench.md")
    sp.set_defaults(fn=cmd_bench)

    sp = sub.add_parser("numerics", help="substep convergence table → results/numerics.md")
    sp.add_argument("--quick", action="store_true")
    sp.add_argument("--out", default="results/numerics.md")
    sp.set_defaults(fn=cmd_numerics)

    sp = sub.add_parser("reproduce", help="reproduce published measurements")
    sp.add_argument("what", choices=["tuttle"])
    sp.add_argument("--quick", action="store_true")
    sp.add_argument("--out", default="results/fidelity")
    sp.set_defaults(fn=cmd_reproduce)

    sp = sub.add_parser("controllers", help="controller benchmark → results/controllers.md")
    sp.add_argument("--quick", action="store_true")
    sp.add_argument("--out", default="results")
    sp.set_defaults(fn=cmd_controllers)

    sp = sub.add_parser("sweep", help="run a sweep spec")
    sp.add_argument("spec")
    sp.add_argument("--out", required=True)
    sp.add_argument("--backend", choices=["local", "ray"], default="local")
    sp.add_argument("--address", default=None)
    sp.add_argument("--workers", type=int, default=None)
    sp.add_argument("--quick", action="store_true", help="shorten every job")
    sp.set_defaults(fn=cmd_sweep)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.fn(args)
    except ValueError as exc:
        print(f"hdgym {args.cmd}: {exc}", file=sys.stderr)
        return 2
    except RuntimeError as exc:
        print(f"hdgym {args.cmd}: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    raise SystemExit(main())
