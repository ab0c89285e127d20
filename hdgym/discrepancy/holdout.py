"""Blind and hold-out cases: full presets with one effect hidden, never used for tuning.

The tuned cases (:mod:`.cases`) are what the workflow's thresholds were set on. The cases
here are only ever evaluated:

* :data:`BLIND` -- the nine records of issue 14 (``hdgym simulate`` on a preset with every
  effect on, diagnosed against the preset with one effect switched off; 6 s, two seeds of
  one command: a ``step`` or ``sine`` validation replays the training run's angles);
* :func:`holdout_cases` -- generated from a fixed seed: every effect on two presets drawn at
  random among those whose parameters give it a size, each with an excitation drawn from the
  ones that can show it (validated on the same kind drawn again), and the base model's
  fitted parameters off nominal by 2-5 %, as a real drive would be.

Each case also measures how much the hidden effect changes its record (:func:`effect_size`,
on the time channels or the effect's own view, the spring curve or the line channels); an
effect that changes it by less than :data:`PRESENT` x that view's measurement noise is not
present in that record (a preset may give it no size at all), and then nothing may be named.

A case *hits* when the hidden effect is named first and cuts at least 80 % of the closable
gap of the validation NMSE (:attr:`Result.gap_cut`: from the NMSE before down to what the
joint the records were made with shows on the same comparison, :mod:`.truth`; where that
truth is not below the NMSE before, of the NMSE itself), or, with nothing (present) hidden,
when nothing is named and the outcome is not "unexplained". The raw cut and the hits it
would give stay beside it in the tables. A miss is *honest* when the outcome says
"unexplained" (also "named; rest unexplained": a named effect left a residual above the
noise level) or lists the hidden effect as untestable rather than "nothing missing".

``python -m hdgym.discrepancy.holdout [--quick] [--set blind|holdout|both] [--seed N]
[--only NAME ...] [--out FILE.md]`` (``--seed``: :data:`FRESH_SEED` is the set that judges,
never tuned on; nothing is written without ``--out``).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from hdgym.files import atomic_write_text, check_out
from hdgym.params import JointParams, preset, preset_names, to_dict
from hdgym.record import Record
from hdgym.sim import Simulator

from . import truth as T
from .diagnosis import HIT_CUT, Diagnosis
from .effect import Scales
from .paths import get_value, set_values
from .pool import call_all
from .registry import REGISTRY, core_params

DURATION = 6.0
"""Seconds per record (the issue's blind records)."""


@dataclass(frozen=True)
class Blind:
    """One blind case: preset, hidden effect (None: nothing hidden), command, output locked.

    ``off``: the base model's fitted parameters are off nominal by up to this share (0: the
    preset's values with the effect's switch alone off, as ``hdgym diagnose --preset P
    --without E``; otherwise its parameters are neutral too, :func:`hidden_off`).
    ``load``: constant external load torque, N m.
    ``validation``: the validation record's command (None: ``command`` again, as issue 14
    defines the blind records; see :func:`records`).
    """

    preset: str
    hidden: str | None
    command: str
    locked: bool = False
    off: float = 0.0
    load: float | None = None
    seed: int = 0
    validation: str | None = None

    @property
    def name(self) -> str:
        lk = ", locked" if self.locked else ""
        off = f", off {100 * self.off:.0f} %" if self.off else ""
        return f"{self.preset} / {self.hidden or 'none'} / {self.command}{lk}{off}"


BLIND: tuple[Blind, ...] = (
    Blind("tuttle-joint1", "position_dependent_friction", "step:1.8"),
    Blind("tuttle-joint3", "kinematic_error", "step:0.30"),
    Blind("tuttle-joint2", "hysteresis", "random:2.0:2", locked=True),
    Blind("hduc20", "stiction", "sine:1.5:0.5"),
    Blind("seyfferth-rh32", "nonlinear_stiffness", "sine:2.0:1", locked=True),
    Blind("hdf40", "load_dependent_friction", "sine:6.0:0.5", load=40.0),
    Blind("wave-drive-50", "viscous_friction", "sine:0.5:1"),
    Blind("seyfferth-rh25", "coulomb_friction", "sine:1.5:0.5"),
    Blind("tuttle-joint2", None, "sine:2.0:0.5"),
)
"""The nine blind records of issue 14 (the first five as the issue gives them; the other
four are the kinds it names, on presets and commands chosen here)."""

EXCITATIONS: dict[str, tuple[str, ...]] = {
    "kinematic_error": ("step", "sine"),
    "position_dependent_friction": ("step", "sine"),
    "hysteresis": ("locked-random", "locked-sine"),
    "nonlinear_stiffness": ("locked-sine", "locked-random"),
    "coulomb_friction": ("sine", "random"),
    "viscous_friction": ("step", "sine"),
    "stribeck_friction": ("sine",),
    "stiction": ("sine", "random"),
    "load_dependent_friction": ("loaded-sine",),
    "amplifier_saturation": ("big-step", "big-sine"),
}
"""Excitations a hold-out case may draw for each effect (the kinds of record that show it)."""


def _command(kind: str, imax: float, rng: np.random.Generator) -> tuple[str, bool, float]:
    """``(command, locked, load fraction)`` of one excitation kind, sized to the current limit."""
    f = float(rng.uniform(0.25, 0.5))
    hz = float(rng.choice([0.5, 1.0, 2.0]))
    # big-step: 1.3-1.55 x the current limit (drawn, so a validation draw differs; saturated)
    spec = {"step": f"step:{f * imax:.3g}", "sine": f"sine:{f * imax:.3g}:{hz:g}",
            "random": f"random:{0.6 * f * imax:.3g}:{2 * hz:g}",
            "big-step": f"step:{(1.05 + f) * imax:.3g}",
            "big-sine": f"sine:{1.3 * imax:.3g}:{hz:g}"}
    spec |= {"locked-random": spec["random"], "locked-sine": spec["sine"],
             "loaded-sine": spec["sine"]}
    if kind not in spec:
        raise ValueError(f"unknown excitation {kind!r}")
    return spec[kind], kind.startswith("locked-"), 0.3 if kind.startswith("loaded-") else 0.0


HOLDOUT_SEED = 14
"""Seed of the first hold-out set (the default ``--seed``; now a development set)."""
DEVELOPMENT_SEEDS = tuple(range(14, 446, 12))  # 14, 26, ..., 434: every fresh set so far
"""Hold-out sets whose failing cases were run one by one while the workflow was changed
(14-110 by 12, each after its first page, on 2026-11-26; 122-206 on 2026-11-27; 230-302 on
2026-11-28; 314 on 2026-12-01; 326-386 on 2026-12-02; 398 on 2026-12-07; 410 half-seen on a
page stopped that day; 422, 434 on 2026-12-08), or that judged two pages and then saw the case
construction change (158: the effect size measured against what the base model lacks,
:func:`hidden_off`, relabelling its stiction cases): no longer untouched. (98-194's stiction
cases ran again when :func:`case_truth` took Stribeck friction out of their truth.)
Seed 218 judged one page, none of its cases run after it; it moved here because that page
listed its misses and the fits changed after it (:func:`.fitting.fit`'s mean-reading pass)."""
PAGE_DEVELOPMENT_SEEDS: tuple[int, ...] = ()
"""Development sets the page reports (none: run them with ``--seed``)."""
FRESH_SEED = 446
"""Seed of the hold-out set that judges the workflow: drawn on 2026-12-08 after seed 434's
page, whose misses were then run one by one as development cases; unseen before its page."""


def validation_command(kind: str, imax: float, seed: int, training: str) -> str:
    """A hold-out case's validation excitation: ``kind`` drawn again by :func:`_command`'s
    rules (another amplitude, frequency or cutoff) from ``default_rng([seed, 2])``, ``seed``
    the case's; a draw equal to ``training`` is drawn again (up to 20 times). The simulator
    is open-loop and deterministic and a record's seed changes only the sensor noise and a
    ``random`` command's realization, so the training command again would replay the
    training run on the angle channels (an overfit model unseen there).
    """
    rng = np.random.default_rng([seed, 2])
    cmd = training
    for _ in range(20):
        cmd = _command(kind, imax, rng)[0]
        if cmd != training:
            break
    return cmd


def holdout_cases(seed: int = HOLDOUT_SEED) -> list[Blind]:
    """Every effect on two presets drawn at random, excitations drawn, base 2-5 % off; the
    validation excitation is the same kind drawn again (:func:`validation_command`)."""
    rng = np.random.default_rng(seed)
    names = [n for n in preset_names()]
    out = []
    for effect, kinds in EXCITATIONS.items():
        # presets whose parameters give the effect a size (neutral values change something)
        has = [n for n in names
               if to_dict(REGISTRY[effect].neutral(preset(n))) != to_dict(preset(n))]
        for k, name in enumerate(rng.choice(has, size=2, replace=False)):
            p = preset(str(name))
            kind = kinds[k % len(kinds)]
            cmd, locked, load = _command(kind, p.amplifier.current_limit, rng)
            t_load = load * p.motor.torque_constant * p.ratio * p.amplifier.current_limit
            s = int(rng.integers(1 << 16))
            val = validation_command(kind, p.amplifier.current_limit, s, cmd)
            out.append(Blind(str(name), effect, cmd, locked, off=0.05,
                             load=t_load if load else None, seed=s, validation=val))
    for k, name in enumerate(rng.choice(names, size=2, replace=False)):
        p = preset(str(name))
        kind = ("sine", "locked-random")[k]
        cmd, locked, _ = _command(kind, p.amplifier.current_limit, rng)
        s = int(rng.integers(1 << 16))
        out.append(Blind(str(name), None, cmd, locked, off=0.05, seed=s,
                         validation=validation_command(kind, p.amplifier.current_limit, s, cmd)))
    return out


def case_truth(case: Blind) -> JointParams:
    """The joint a case's records are made with: the preset, every effect on, except that a
    hold-out case hiding stiction has Stribeck friction off.

    The kernel holds a stuck joint at the breakaway torque when stiction *or* Stribeck
    friction is on (eq. 7), and every preset has both. Hidden beside Stribeck friction,
    stiction is only the static friction excess, which the base model's own Stribeck
    friction represents exactly (its breakaway is a fitted parameter): the base model
    family holds the truth, so "nothing missing" was the right answer to a case labelled
    present (six such cases on development seeds 98-170) and a base fit that stalled at
    no excess read "unexplained" (seed 182, hduc20 / stiction: breakaway excess 0.0007
    against 0.63 N m). Without Stribeck friction, hidden stiction is a static level
    nothing in the base model holds, as on a drive whose friction does not fall with speed.
    The blind case keeps the preset as issue 14's ``hdgym simulate`` command made it.
    """
    p = preset(case.preset)
    if case.hidden == "stiction" and case.off and "stribeck_friction" in p.effects:
        return p.without("stribeck_friction")
    return p


def hidden_off(truth: JointParams, hidden: str, neutral: bool = True) -> JointParams:
    """``truth`` with the effect ``hidden`` switched off and (``neutral``) its parameters
    neutral: what a case's base model lacks (before its offsets, :func:`base_model`), and
    what its effect size is measured against (:func:`effect_size`). Without ``neutral``,
    the switch alone, as ``hdgym diagnose --without`` hands the workflow the preset (the
    blind cases, which issue 14 defines by that command).

    The switch alone can hide less than the effect: the kernel holds a stuck joint at the
    breakaway torque when stiction *or* Stribeck friction is on (eq. 7), so on a preset with
    both, stiction switched off changes no record, while its neutral breakaway (the static
    friction excess) removes what both read. The neutral values are part of what is hidden
    (the Coulomb friction's takes the friction ripple with it, the tanh hysteresis's the
    startup torque's growth with the load history).
    """
    off = truth.without(hidden)
    return REGISTRY[hidden].neutral(off) if neutral else off


def unperturbed_base(case: Blind, truth: JointParams) -> JointParams:
    """A case's base model before its offsets: :func:`hidden_off`, the switch alone on the
    blind cases (off 0, as the issue's command), with its parameters neutral otherwise."""
    return truth if case.hidden is None else hidden_off(truth, case.hidden,
                                                        neutral=bool(case.off))


def base_model(case: Blind, truth: JointParams) -> JointParams:
    """The preset with the hidden effect off (:func:`hidden_off`: neutral too, except on the
    blind cases), the fitted parameters off nominal.

    Every parameter the base fit adjusts is scaled by ``1 +- U(0.4 off, off)`` (random sign,
    seeded by the case).
    """
    p = unperturbed_base(case, truth)
    if not case.off:
        return p
    s = Scales(torque=10.0, speed=1.0, torsion=1e-3, current=1.0, locked=case.locked)
    paths = [fp.path for fp in core_params(p, s)]
    for e in p.effects:
        paths += [fp.path for fp in REGISTRY[e].fit_params(p, s)]
    rng = np.random.default_rng(1000 + case.seed)
    values = {}
    for path in dict.fromkeys(paths):
        f = rng.uniform(0.4 * case.off, case.off) * (1 if rng.uniform() < 0.5 else -1)
        values[path] = get_value(p, path) * (1 + f)
    return set_values(p, values)


def records(case: Blind, truth: JointParams) -> tuple[Record, Record]:
    """Training (seed 1) and validation (seed 2) records, as ``hdgym simulate`` makes them.

    The validation record runs :attr:`Blind.validation` (a hold-out case's excitation drawn
    again) with its own seed: sensor noise and a ``random`` command's realization
    (:meth:`hdgym.sim.Simulator.run` seeds both). A blind case keeps issue 14's one command
    for both records; its validation is then as independent as that command allows: a
    ``random`` command is a different realization, while a ``step`` or ``sine`` fixes the
    noise-free run: its validation differs from training only in the current and torque
    noise (the encoder angles are the training run's again).
    """
    out = []
    for seed, cmd in ((1, case.command), (2, case.validation or case.command)):
        sim = Simulator(truth, locked_output=case.locked)
        rec = sim.run(cmd, DURATION, seed=seed, load_torque=case.load)
        out.append(Record(dict(rec.columns), dict(rec.meta), f"{case.name} seed {seed}"))
    return out[0], out[1]


def effect_size(case: Blind, truth: JointParams, train: Record, command: str | None = None,
                seed: int = 1) -> tuple[float, float]:
    """How much the hidden effect changes a record of the case, and the record's noise.

    ``train``: the record (the training record by default; the validation record with
    ``command`` its command and ``seed`` 2, which realizes a ``random`` command).
    Both runs of the command are simulated without sensor noise, with and without
    the hidden effect (as the base model lacks it: :func:`unperturbed_base`; the switch alone
    left stiction "not present" on every preset, all of which have Stribeck friction, while
    the base model also lacked the breakaway excess: development seed 134, wave-drive-50 /
    stiction / sine:0.411:0.5, where naming stiction cut the NMSE by 70 %); the change of
    the comparison channels is an NMSE, percent, mean over channels, against the measured
    record's variance, beside the record's measurement-noise NMSE
    (:func:`.noise.noise_nmse`); or those of the effect's own view where it stands higher
    above that view's noise (:func:`.truth.view_size`: the spring curve, the line channels).
    """
    from . import residuals as R
    from .problem import Problem

    prob = Problem(train, truth)
    if case.hidden is None:
        return 0.0, prob.noise["mean"]
    runs = []
    for p in (truth, unperturbed_base(case, truth)):
        rec = Simulator(p, locked_output=case.locked, sensors=False).run(
            command or case.command, DURATION, seed=seed, load_torque=case.load)
        raw = R.Raw(np.asarray(rec.motor_angle), None if case.locked else rec.output_angle,
                    rec.output_torque, rec.motor_current)
        runs.append(R.channels(raw, prob.names, prob.ratio, prob.dt, prob.cutoff))
    size = float(np.mean([100 * np.mean((runs[0][k] - runs[1][k]) ** 2) / prob.sigma2[k]
                          for k in prob.names]))
    seen = T.view_size(prob, truth, unperturbed_base(case, truth), REGISTRY[case.hidden].compare)
    if seen is not None and seen[0] * prob.noise["mean"] > size * seen[1]:
        return seen
    return size, prob.noise["mean"]


PRESENT = 3.0
"""A hidden effect is present in a record when it changes the channels by more than this
factor times the record's measurement-noise NMSE (:func:`effect_size`)."""


@dataclass
class Result:
    """One case's diagnosis and what the case alone knows about it.

    ``size``, ``noise``: :func:`effect_size` on the training record; ``val_size``,
    ``val_noise``: on the validation record. ``truth``: the NMSE, percent, of the joint the
    records were made with on the comparison the diagnosis reports before and after on
    (:func:`.truth.truth_nmse`: the floor no model goes below); ``floor``: the workflow's own
    estimate of it, the one its outcome was judged by (:attr:`.diagnosis.Diagnosis.floor`);
    ``noise_true`` and ``noise_est``: the validation record's sensor noise per channel and
    its mean (:func:`.truth.true_noise_nmse`) and what :func:`.noise.noise_nmse` estimates
    from the record, NMSE percent.
    """

    case: Blind
    diagnosis: Diagnosis
    seconds: float
    size: float = 0.0
    noise: float = 0.0
    truth: float = math.nan
    val_size: float = 0.0
    val_noise: float = 0.0
    floor: float = math.nan
    noise_true: dict[str, float] = field(default_factory=dict)
    noise_est: dict[str, float] = field(default_factory=dict)

    @property
    def gap_cut(self) -> float:
        """Share of the closable gap (before - truth) the diagnosis closed (nan: unknown)."""
        d = self.diagnosis
        return T.gap_cut(d.nmse_before, d.nmse_after, self.truth)

    @property
    def present(self) -> bool:
        """Whether the hidden effect shows in either record at all (see :data:`PRESENT`):
        the workflow searches the validation record too (the roles swapped), and an effect
        only it shows is still missing (development seed 254, tuttle-joint3 /
        position_dependent_friction / sine:0.159:1: 6e-6 % on a training run that barely
        moves, 29 % on its validation run at 0.284 A)."""
        return self.case.hidden is not None and (self.size > PRESENT * self.noise
                                                 or self.val_size > PRESENT * self.val_noise)

    @property
    def cut(self) -> float:
        """The cut a hit is judged by: of the closable gap (:attr:`gap_cut`) when the truth
        is known and below the NMSE before, else of the NMSE itself (the raw cut)."""
        g = self.gap_cut
        return self.diagnosis.nmse_cut if math.isnan(g) else g

    def _hit(self, cut: float) -> bool:
        d = self.diagnosis
        if not self.present:  # nothing (visible) hidden: nothing may be named
            return not d.missing_effects and d.outcome != "unexplained"
        found = d.missing_effects
        return bool(found) and found[0] == self.case.hidden and cut >= HIT_CUT

    @property
    def hit(self) -> bool:
        """The hidden effect named first and :attr:`cut` (the closable gap's) >= HIT_CUT
        (nothing present hidden: nothing named and not "unexplained")."""
        return self._hit(self.cut)

    @property
    def raw_hit(self) -> bool:
        """As :attr:`hit`, judged by the raw cut of the NMSE (before the truth floor was known)."""
        return self._hit(self.diagnosis.nmse_cut)

    @property
    def honest(self) -> bool:
        """A hit, or a miss that does not claim "nothing missing"."""
        d = self.diagnosis
        if self.hit:
            return True
        if not self.present:  # nothing (visible) hidden: naming an effect is not honest
            return not d.missing_effects
        return d.outcome.endswith("unexplained") or self.case.hidden in d.untestable


def run(case: Blind, quick: bool = False) -> Result:
    from .problem import Problem
    from .workflow import diagnose

    t0 = time.perf_counter()
    truth = case_truth(case)
    train, val = records(case, truth)
    diag = diagnose(train, base_model(case, truth), val, quick=quick)
    seconds = time.perf_counter() - t0
    size, noise = effect_size(case, truth, train)
    val_size, val_noise = effect_size(case, truth, val, case.validation, seed=2)
    clean = Simulator(truth, locked_output=case.locked, sensors=False).run(
        case.validation or case.command, DURATION, seed=2, load_torque=case.load)
    vt = Problem(val, truth, channels=diag.problem.time_names if diag.problem else diag.channels)
    return Result(case, diag, seconds, size, noise, truth=T.truth_nmse(diag, truth),
                  floor=math.nan if diag.floor is None else diag.floor,
                  noise_true=T.true_noise_nmse(vt, clean),
                  noise_est=dict(vt.noise), val_size=val_size, val_noise=val_noise)


def table(results: list[Result]) -> str:
    lines = ["| case | effect NMSE % (noise %), training / validation | outcome | "
             "found (in order) | NMSE before % | NMSE after % | truth % | cut | gap cut | hit | "
             "honest | next experiment | s |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        d = r.diagnosis
        nxt = ", ".join(f"`{x}`" for x in d.next_experiments) or "-"
        size = (f"{r.size:.2g} ({r.noise:.2g}) / {r.val_size:.2g} ({r.val_noise:.2g})"
                + ("" if r.present or r.case.hidden is None else ": not present"))
        found = ", ".join(d.missing_effects) or "none"
        if d.compare in ("spring", "lines"):  # before and after are NMSE of that view
            found += " (spring curve)" if d.compare == "spring" else " (line channels)"
        gap = "-" if math.isnan(r.gap_cut) else f"{100 * r.gap_cut:.0f} %"
        lines.append(f"| {r.case.name} | {size} | {d.outcome} | {found} "
                     f"| {d.nmse_before:.3g} | {d.nmse_after:.3g} | {r.truth:.3g} "
                     f"| {100 * d.nmse_cut:.0f} % | {gap} | "
                     f"{'yes' if r.hit else '**no**'} | {'yes' if r.honest else '**no**'} | "
                     f"{nxt} | {r.seconds:.1f} |")
    return "\n".join(lines)


def summary(results: list[Result]) -> str:
    n = len(results)
    hits = sum(r.hit for r in results)
    raw = sum(r.raw_hit for r in results)
    honest = sum(r.honest for r in results)
    return (f"{hits} of {n} hit ({100 * hits / max(n, 1):.0f} %; judged by the raw cut: {raw} "
            f"of {n}); {honest} of {n} hit or say unexplained/untestable instead of \"nothing "
            f"missing\" ({100 * honest / max(n, 1):.0f} %).")


def sections(sets: list[tuple[str, list[Blind]]], results: Iterator[Result]) -> list[str]:
    """Markdown lines: a :func:`table` and :func:`summary` per ``(title, cases)`` of ``sets``,
    of the results ``results`` yields in order (each printed as it comes)."""
    text = []
    for title, cases in sets:
        done = []
        for _ in cases:
            done.append(r := next(results))
            print(f"{r.case.name}: {r.diagnosis.outcome}, found {r.diagnosis.missing_effects}, "
                  f"gap cut {100 * r.gap_cut:.0f} %, hit {r.hit} ({r.seconds:.1f} s); noise true"
                  " / estimated: " + ", ".join(f"{k} {r.noise_true[k]:.2g} / {r.noise_est[k]:.2g}"
                                              for k in r.noise_true), flush=True)
        text += [f"### {title}", "", table(done), "", summary(done), ""]
    return text


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m hdgym.discrepancy.holdout",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer least-squares iterations")
    ap.add_argument("--set", choices=["blind", "holdout", "both"], default="both")
    ap.add_argument("--only", nargs="*", help="case names (as printed) to run")
    ap.add_argument("--out", default=None, help="write the tables (markdown) here")
    ap.add_argument("--jobs", type=int, default=1, help="cases at once (worker processes)")
    ap.add_argument("--seed", type=int, default=HOLDOUT_SEED,
                    help="draw the hold-out cases with this seed (default %(default)s, a "
                    f"development set; {FRESH_SEED}: the fresh set that judges, never tune on it)")
    args = ap.parse_args(argv)
    if args.out:
        check_out(args.out, args.quick)
    sets = {"blind": list(BLIND), "holdout": holdout_cases(args.seed)}
    chosen = [(w, [c for c in sets[w] if not args.only or c.name in args.only])
              for w in (["blind", "holdout"] if args.set == "both" else [args.set])]
    runs = call_all([partial(run, c, quick=args.quick) for _, cs in chosen for c in cs], args.jobs)
    out = "\n".join(sections(chosen, runs))
    print(out)
    if args.out:
        atomic_write_text(args.out, out + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
