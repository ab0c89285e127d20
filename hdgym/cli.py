"""The ``hdgym`` command: simulate harmonic-drive joints, reproduce published
measurements, benchmark controllers, diagnose missing effects, run sweeps and
rebuild the results pages.

Outputs go where ``--out`` says (default: under ``runs/``); the committed pages
in ``results/`` are written only by ``--out results/...`` or ``hdgym results``,
and never by a ``--quick`` run. Long jobs show a progress bar on stderr
(``TQDM_DISABLE=1`` hides it) and say when numba compiles (first run only).

Exit code 0 on success, 2 on bad input with one line on stderr naming what
is wrong, 1 when a simulation fails (e.g. diverges), 130 on Ctrl-C.
"""

from __future__ import annotations

import argparse
import sys
import textwrap
from collections.abc import Sequence
from pathlib import Path

from hdgym.effects import EFFECTS
from hdgym.files import atomic_write_text, check_out
from hdgym.results_pages import PAGES

QUICK_HELP = "shorter runs for a first look or a smoke test (never into results/)"


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


def params_header() -> str:
    """The comment block `hdgym params` puts above a preset: what a file must hold, and the
    default every field left out of a file takes."""
    from dataclasses import MISSING, fields, is_dataclass

    from hdgym.params.parts import PARTS, FrictionSide, Harmonic, Ripple

    def plain(v: object) -> str:  # a default as TOML writes it
        if isinstance(v, bool):
            return str(v).lower()
        if isinstance(v, tuple):
            return "[" + ", ".join(map(plain, v)) + "]"
        return f'"{v}"' if isinstance(v, str) else repr(v)

    lines = ["# hdgym joint parameters, SI units (rad, s, kg m^2, N m, A, V, ohm).",
             "# Edit and use with --params FILE. A file must hold [motor], [transmission],",
             "# [compliance], [load] and [amplifier] with their required fields; any other",
             "# section or field left out takes the default listed here ([effects] on: every",
             "# effect):"]
    tables = [*PARTS.items(), ("friction.input/output", FrictionSide),
              ("[friction.*.ripple]", Ripple), ("[kinematic_error.harmonics]", Harmonic)]
    for key, cls in tables:
        need = [f.name for f in fields(cls) if f.default is MISSING
                and f.default_factory is MISSING]
        opt = [f"{f.name} = {plain(f.default)}" for f in fields(cls)
               if f.default is not MISSING and not is_dataclass(f.default)]
        text = f"#   [{key.strip('[]')}]" + (f" required: {', '.join(need)};" if need else "")
        text += f" defaults: {', '.join(opt)}" if opt else ""
        lines += textwrap.wrap(text, 96, subsequent_indent="#       ", break_on_hyphens=False)
    return "\n".join(lines) + "\n\n"


def cmd_params(args: argparse.Namespace) -> int:
    from hdgym import params

    if args.list:
        for name in params.preset_names():
            print(name)
        return 0
    if not args.preset:
        raise ValueError("give --preset NAME (see --list), and --out FILE.toml to write a file")
    text = params_header() + params.dumps(params.preset(args.preset))
    if args.out:
        atomic_write_text(args.out, text)
        print(f"wrote {args.out}")
    else:
        sys.stdout.write(text)
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    from hdgym import bench

    check_out(args.out, args.quick)
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

    check_out(args.out, args.quick)
    numerics.write_table(Path(args.out), quick=args.quick)
    print(f"wrote {args.out}")
    return 0


def cmd_reproduce(args: argparse.Namespace) -> int:
    from hdgym import reproduce

    check_out(args.out, args.quick)
    ok = reproduce.run(args.what, Path(args.out), quick=args.quick)
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
    from hdgym.discrepancy.command import diagnose_files

    report = diagnose_files(args.record, _params(args), out=Path(args.out),
                            validate=args.validate)
    found = ", ".join(report["missing_effects"]) or "none"
    print(f"missing effects: {found}; NMSE {report['nmse_before']:.3g} % -> "
          f"{report['nmse_after']:.3g} %; wrote {args.out}/report.md")
    return 0


def cmd_controllers(args: argparse.Namespace) -> int:
    from controllers import benchmark

    check_out(args.out, args.quick)
    benchmark.run(Path(args.out), quick=args.quick)
    print(f"wrote {args.out}")
    return 0


def cmd_sweep(args: argparse.Namespace) -> int:
    from hdgym.sweep import run_sweep

    result = run_sweep(args.spec, Path(args.out), backend=args.backend, address=args.address,
                       workers=args.workers, quick=True if args.quick else None,
                       summary_dir=args.summary_dir)
    return 1 if result.errors else 0


def cmd_results(args: argparse.Namespace) -> int:
    import shlex
    import subprocess

    from hdgym.progress import bar, step
    from hdgym.results_pages import table

    root = args.out or ("runs/results-quick" if args.quick else "results")
    check_out(root, args.quick)
    if args.list:
        print(table(root))
        return 0
    names = [p.name for p in PAGES]
    unknown = [n for n in args.only or [] if n not in names]
    if unknown:
        raise ValueError(f"--only: unknown page {unknown[0]!r}; known: {', '.join(names)}")
    pages = [p for p in PAGES if not args.only or p.name in args.only]
    with bar(total=len(pages), desc="hdgym results", unit="page", leave=True) as b:
        for page in pages:
            argv = page.command(root, args.quick)
            b.set_postfix_str(page.name)
            b.write(f"$ {shlex.join(argv)}", file=sys.stderr)
            run = [sys.executable, "-m", "hdgym.cli", *argv[1:]] if argv[0] == "hdgym" else \
                [sys.executable, *argv[1:]]
            code = subprocess.run(run).returncode
            if code not in page.written_codes:
                raise RuntimeError(f"{page.name}: `{shlex.join(argv)}` failed; the pages "
                                   f"before it are rebuilt, the rest are not")
            if code:
                b.write(f"{page.name}: exit {code} (a check failed; the page says which)",
                        file=sys.stderr)
            step(b, page.name)
    print(f"rebuilt {len(pages)} page(s) under {root}/")
    return 0


def _experiment_epilog() -> str:
    from hdgym.discrepancy.experiments import PROTOCOLS

    rows = [f"  {name:22s} {spec['use']} ({spec['duration']:g} s"
            + (", output locked)" if spec["locked"] else ")") for name, spec in PROTOCOLS.items()]
    return "protocols:\n" + "\n".join(rows)


def _sweep_epilog() -> str:
    from hdgym.sweep import spec_names

    return (
        "The spec is a TOML file: [sweep] name, presets (bundled names or TOML files),\n"
        "scenarios, seeds (a count or a list), quick; optional [spreads] (relative\n"
        "uniform spreads per parameter path, e.g. \"compliance.stiffness\" = 0.3), [grid]\n"
        "(explicit values, product taken), [scenario.NAME] options, [[controllers]] and\n"
        "[[agents]]. Every job is one preset x drawn drive x controller/agent x seed;\n"
        "DIR/results.csv gets one row per job and re-running resumes. The full format is\n"
        "in the docstring of hdgym.sweep.spec.\n\n"
        f"bundled specs (give the name or a path): {', '.join(spec_names())}\n"
        "example: hdgym sweep controllers --out runs/ctl --quick")


def _results_epilog() -> str:
    return "pages, in build order:\n" + "\n".join(
        f"  {p.name:18s} results/{p.path}: {p.what}" for p in PAGES)


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="hdgym", description=__doc__.replace("``", ""),
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True, metavar="COMMAND")
    raw = argparse.RawDescriptionHelpFormatter

    sp = sub.add_parser("simulate", help="run a command signal and write a record CSV",
                        description="Run a joint open loop on a current command and write the "
                        "record (time series, SI units) to a CSV.")
    _add_joint(sp)
    sp.add_argument("--locked-output", action="store_true",
                    help="clamp the output port (torsion experiments)")
    sp.add_argument("--command", required=True,
                    help="step:A | ramp:A0:A1 | sine:A:HZ | chirp:A:HZ0:HZ1 | random:A:CUTOFF_HZ "
                         "| FILE.csv (columns time,current_command; A)")
    sp.add_argument("--duration", type=float, required=True, help="s")
    sp.add_argument("--load-torque", type=float, default=None, help="external load, N m")
    sp.add_argument("--seed", type=int, default=0)
    sp.add_argument("--true-states", action="store_true",
                    help="record true states instead of what the sensors measure")
    sp.add_argument("--out", required=True, help="record CSV to write")
    sp.set_defaults(fn=cmd_simulate)

    sp = sub.add_parser("params", help="print or write a preset's parameters (TOML) to edit",
                        description="Print a preset's parameters as TOML (every field, with "
                        "units and sources), or write them to --out to edit and use with "
                        "--params FILE.")
    sp.add_argument("--preset", help="bundled preset name")
    sp.add_argument("--out", help="TOML file to write (default: print to stdout)")
    sp.add_argument("--list", action="store_true", help="list the presets")
    sp.set_defaults(fn=cmd_params)

    sp = sub.add_parser("diagnose", help="find and name the effects a model misses",
                        description="Fit the model to a record, localize the residual, name "
                        "the missing effect, add it, refit, repeat; writes report.md + "
                        "report.json (and figures) to --out.")
    sp.add_argument("record", help="measured record CSV (see hdgym/record.py for the format)")
    _add_joint(sp)
    sp.add_argument("--validate", help="a second record CSV to validate the fitted model on")
    sp.add_argument("--out", required=True, help="report folder")
    sp.set_defaults(fn=cmd_diagnose)

    sp = sub.add_parser("experiment", help="identification protocols as command signals",
                        description="Simulate an identification protocol on a joint and write "
                        "the record; its current_command column also drives a real rig.",
                        epilog=_experiment_epilog(), formatter_class=raw)
    sp.add_argument("name", help="protocol (listed below)")
    _add_joint(sp)
    sp.add_argument("--duration", type=float, default=None, help="s (default: the protocol's)")
    sp.add_argument("--seed", type=int, default=0)
    sp.add_argument("--out", required=True, help="record CSV to write")
    sp.set_defaults(fn=cmd_experiment)

    sp = sub.add_parser("bench", help="speed benchmarks (ratios against references)",
                        description="Speed benchmarks, as ratios against references measured "
                        "in the same run; writes a markdown table.")
    sp.add_argument("--quick", action="store_true", help=QUICK_HELP)
    sp.add_argument("--soak", action="store_true",
                    help="add a million-step soak run per preset (long; not in CI)")
    sp.add_argument("--out", default="runs/bench.md",
                    help="markdown file to write (default %(default)s; the committed page is "
                    "results/bench.md)")
    sp.set_defaults(fn=cmd_bench)

    sp = sub.add_parser("numerics", help="substep convergence table",
                        description="Substep convergence per preset: error against a run with "
                        "many more substeps; writes a markdown table.")
    sp.add_argument("--quick", action="store_true", help=QUICK_HELP)
    sp.add_argument("--out", default="runs/numerics.md",
                    help="markdown file to write (default %(default)s; the committed page is "
                    "results/numerics.md)")
    sp.set_defaults(fn=cmd_numerics)

    sp = sub.add_parser("reproduce", help="reproduce published measurements",
                        description="Reproduce the published measurements of a study; writes "
                        "fidelity.md and figures to --out. Exit 1 if a check fails.")
    sp.add_argument("what", choices=["tuttle", "seyfferth", "all"],
                    help="the study (all: every study on one page)")
    sp.add_argument("--quick", action="store_true", help=QUICK_HELP)
    sp.add_argument("--out", default="runs/fidelity",
                    help="folder to write (default %(default)s; the committed pages are "
                    "results/fidelity)")
    sp.set_defaults(fn=cmd_reproduce)

    sp = sub.add_parser("controllers", help="controller benchmark (PID, KE feedforward, "
                        "repetitive, DOB)",
                        description="Controller benchmark on tracking, load-step and "
                        "point-to-point scenarios; writes OUT/controllers.md and "
                        "OUT/controllers/*.png.")
    sp.add_argument("--quick", action="store_true", help=QUICK_HELP)
    sp.add_argument("--out", default="runs",
                    help="folder to write (default %(default)s; the committed page is "
                    "results/controllers.md, from --out results)")
    sp.set_defaults(fn=cmd_controllers)

    sp = sub.add_parser("sweep", help="run a sweep spec (presets x drives x controllers x seeds)",
                        description="Run a sweep: a spec expanded into independent jobs on a "
                        "local process pool or Ray, one results.csv row per job, then a "
                        "summary (OUT/summary.md, OUT/summary.png).",
                        epilog=_sweep_epilog(), formatter_class=raw)
    sp.add_argument("spec", help="spec TOML file or bundled spec name")
    sp.add_argument("--out", required=True, help="output folder (results.csv, spec.toml, summary)")
    sp.add_argument("--summary-dir", default=None,
                    help="also copy the summary to DIR/<name>.md and .png")
    sp.add_argument("--backend", choices=["local", "ray"], default="local")
    sp.add_argument("--address", default=None, help="Ray cluster address (--backend ray)")
    sp.add_argument("--workers", type=int, default=None, help="processes (default: all cores)")
    sp.add_argument("--quick", action="store_true", help="shorten every job; " + QUICK_HELP)
    sp.set_defaults(fn=cmd_sweep)

    sp = sub.add_parser("results", help="rebuild every results page, in order",
                        description="Rebuild the results pages by running the command of each "
                        "(the README's results table), physics first. Takes a long time "
                        "(hours with the soak and RL runs); --quick runs the quick variants "
                        "into runs/results-quick/ in minutes.",
                        epilog=_results_epilog(), formatter_class=raw)
    sp.add_argument("--quick", action="store_true", help=QUICK_HELP)
    sp.add_argument("--out", default=None,
                    help="output root (default results, or runs/results-quick with --quick)")
    sp.add_argument("--only", nargs="+", metavar="PAGE", help="rebuild only these pages")
    sp.add_argument("--list", action="store_true",
                    help="print the pages and their commands (markdown), run nothing")
    sp.set_defaults(fn=cmd_results)
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    from hdgym.progress import announce_compiles

    try:
        args = build_parser().parse_args(argv)
    except KeyboardInterrupt:
        print("hdgym: interrupted", file=sys.stderr)
        return 130
    try:
        with announce_compiles():
            return args.fn(args)
    except ValueError as exc:
        print(f"hdgym {args.cmd}: {exc}", file=sys.stderr)
        return 2
    except RuntimeError as exc:
        print(f"hdgym {args.cmd}: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"hdgym {args.cmd}: interrupted; files already finished are kept, none is "
              "half-written", file=sys.stderr)
        return 130
    except MemoryError:
        print(f"hdgym {args.cmd}: out of memory; ask for a shorter run", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"hdgym {args.cmd}: {exc.filename or ''}: {exc.strerror or exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
