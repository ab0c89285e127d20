"""The blind and hold-out sections of results/discrepancy.md: the page's words for how the
cases are made and judged, and their tables (:mod:`.holdout` makes and runs the cases)."""

from __future__ import annotations

from collections.abc import Iterator

from .holdout import (
    BLIND,
    DEVELOPMENT_SEEDS,
    FRESH_SEED,
    PAGE_DEVELOPMENT_SEEDS,
    Blind,
    Result,
    holdout_cases,
    sections,
)


def page_sets(quick: bool = False) -> list[tuple[str, list[Blind]]]:
    """The page's blind and hold-out sets, ``(title, cases)``: the blind cases, and unless
    ``quick`` the development and fresh hold-out sets (:data:`.holdout.PAGE_DEVELOPMENT_SEEDS`,
    :data:`.holdout.FRESH_SEED`)."""
    sets = [("Blind (issue 14)", list(BLIND))]
    if not quick:
        sets += [(f"Development hold-out (seed {s})", holdout_cases(s))
                 for s in PAGE_DEVELOPMENT_SEEDS]
        sets.append((f"Fresh hold-out (seed {FRESH_SEED})", holdout_cases(FRESH_SEED)))
    return sets


def page_section(sets: list[tuple[str, list[Blind]]], results: Iterator[Result],
                 quick: bool = False) -> str:
    """The blind and hold-out sections of results/discrepancy.md for :func:`page_sets`
    ``sets``, whose cases' results ``results`` yields in order (:func:`.holdout.run` of each,
    :func:`.pool.call_all`; printed as they come).

    Every case runs the workflow's full fit settings, what ``hdgym diagnose`` runs (a
    case's verdict can depend on the fit's budget, so the page judges the settings users
    get); ``quick`` (the blind cases only, with the quick fit settings) says so on the page.
    """
    from .floor import CURVE_SHARE
    from .outcome import CARRY_FACTOR, FLOOR_FACTOR, NOISE_FACTOR, RESOLVED
    from .search import VALIDATION_GAIN

    parts = ["", "## Blind and hold-out cases (never used for tuning)", "",
             "Made by `hdgym.discrepancy.holdout` (run here by the same command): full presets "
             "with every effect on; the base model is the preset with one effect switched off (its"
             " parameters neutral). *Blind*: the nine records of issue 14 (6 s, `hdgym simulate`, "
             "seeds 1 and 2 of one command), the base at the preset's values; the simulator is "
             "deterministic and the seed changes only the current and torque noise and a random "
             "command's realization, so a blind step or sine validation record has the training "
             "record's angles (the command, as the issue defines it, allows no more). *Hold-out*: "
             "every effect on two presets drawn with a fixed seed among those whose parameters "
             "give it a size, an excitation drawn from those that can show it, and every fitted "
             "base parameter off nominal by 2-5 % (a case hiding stiction is made with "
             "Stribeck friction off, `holdout.case_truth`: beside it, stiction is only the "
             "breakaway excess the base model's own Stribeck friction fits; hiding Coulomb "
             "friction takes the friction ripple with it, so position-dependent friction, left "
             "on with no ripple line to fit, is missing too and a candidate, "
             "`registry.lacks`); the validation "
             "record (seed 2) runs the same "
             "kind of excitation drawn again, seeded by the case (another amplitude, frequency or "
             "cutoff; `holdout.validation_command`). *Effect NMSE*: how much the hidden effect "
             "changes each record, training and validation (noise-free runs with and without "
             "it), beside the record's measurement-noise NMSE; below 3 x the noise on both it is "
             "*not present* (shown on either, it is missing: the roles-swapped search reads "
             "the validation record). *Truth*: the NMSE "
             "of the joint the records were made with (its true parameters, every effect on) on "
             "the comparison before and after are reported on (same horizon, channels, time or "
             "spring curve; `hdgym.discrepancy.truth`): the floor no model goes below, unless the "
             "comparison itself (restarts every horizon) favours a fitted model. *Gap cut*: the "
             "share of the closable gap, (before - after) / (before - truth), closed (\"-\" when "
             "the truth is not below before). Where the named model's validation NMSE is not "
             "at its own floor (below), the named model and the base model are each refitted "
             "on the training and validation records together, so before and after are both "
             "of a fit that saw the validation record; kept where the effect still cuts the "
             f"base refit's validation NMSE by {100 * VALIDATION_GAIN:g} % "
             "(`hdgym.discrepancy.settle.settle_named`). A case *hits* when the hidden effect "
             "is named first and the gap cut (the raw cut where there is none) is >= 80 % "
             "(nothing present hidden: nothing named and not \"unexplained\"); the summary "
             "also counts the hits by the raw cut. A miss is *honest* when the outcome says "
             "\"unexplained\" or the hidden effect is listed as untestable on the record. "
             "Outcomes: *named* when the final NMSE "
             f"is within {FLOOR_FACTOR:g} x what the final model shows on a record it made "
             "itself (its own floor, `hdgym.discrepancy.floor.floor_nmse`, mean over channels; "
             "the base model's where that is lower, `hdgym.discrepancy.outcome.judge`; "
             "`hdgym.discrepancy.outcome.FLOOR_FACTOR`), else *named; rest unexplained*; with "
             "nothing named, *nothing missing* when the final NMSE is within "
             f"{NOISE_FACTOR:g} x the measurement-noise NMSE (`hdgym.discrepancy.noise`), or at "
             f"most {RESOLVED:g} % and within {FLOOR_FACTOR:g} x the base model's own floor "
             "(unless every effect the base model lacks is untestable on the record) "
             "(`NOISE_FACTOR`, `RESOLVED`, set on the tuned cases; `outcome.resolved`), and "
             "every channel within that factor of its own noise NMSE or at most "
             f"{RESOLVED:g} % (one noisy channel may not lend its noise to the others: "
             "`outcome.noisy_channel_hides`), else *unexplained*; either is "
             "*unexplained* also when one channel alone is above 3 x its floor and beyond what the"
             " fitted parameters can change it (`hdgym.discrepancy.floor`). With nothing named "
             "it is *unexplained* also when the validation NMSE, the base model refitted on both "
             f"records, stays more than {CARRY_FACTOR:g} x what the base model reaches on the "
             "training record alone (`hdgym.discrepancy.outcome.carry_gap`); a validation record "
             "whose channels stand nowhere above their noise does not judge, the training "
             "record does (`outcome.judged_record`). With nothing named it is *unexplained* "
             "also when a candidate cut the training cost by at least "
             f"{100 * VALIDATION_GAIN:g} % against the base model refitted until it converged "
             "and carried over to the validation record, yet fell short of being named (a "
             "residual an effect explains part of is not fit slack; not from a candidate "
             "the record's noise would hide at the size it suggests; "
             "`hdgym.discrepancy.outcome.partial_evidence`). On a locked output "
             "whose time channels show nothing, the spring curve (motor angle over bins of the "
             "measured torque and its direction, one run; `hdgym.discrepancy.spring`) is searched "
             "for the spring's effects; a case found there reports before and after on the curve "
             "(*found* says \"(spring curve)\"); a curve left above its noise reads "
             "*unexplained* only when a missing effect explains at least "
             f"{100 * CURVE_SHARE:g} % of it (`hdgym.discrepancy.floor.CURVE_SHARE`). The "
             "prediction horizon is chosen per record and "
             "again after each effect added, and other horizons (longer ones on which the model "
             "drifts, the shortest) are searched when nothing is found at it "
             "(`hdgym.discrepancy.problem.Problem.choose_horizon`, "
             "`hdgym.discrepancy.search.escalate`). These cases run the workflow's full fit "
             "settings, what `hdgym diagnose` runs (earlier pages ran the quick ones, fewer "
             "least-squares iterations; a single case's verdict can move with the fit's budget). "
             "Hold-out sets: seeds "
             f"{', '.join(map(str, DEVELOPMENT_SEEDS))} were each the fresh set of an earlier "
             "page and then had their failing cases run one by one to find their causes while "
             "the workflow was changed (so they are no longer untouched: development sets; "
             + (f"seed {', '.join(map(str, PAGE_DEVELOPMENT_SEEDS))} is reported here, the "
                "others run" if PAGE_DEVELOPMENT_SEEDS else "they run") +
             " with `python -m hdgym.discrepancy.holdout --seed S`), and seed "
             f"{FRESH_SEED}, drawn the same way after those changes and never run before this "
             "page: the set to judge by.", ""]
    if quick:
        parts += ["(A --quick run: the hold-out cases are skipped.)", ""]
    parts += sections(sets, results)
    return "\n".join(parts) + "\n"
