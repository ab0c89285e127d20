"""Name, add, refit, repeat: find the physical effects a model misses.

1. Fit the given base model to the record (:func:`.fitting.fit` over the
   core parameters and those of every effect that is on) and localize the
   residual (:func:`.residuals.localize`).
2. Rank every effect that is off (and that the record can show) by how much
   of the residual it explains, two ways: the effect's signature regressors
   (:func:`.residuals.signature`) and its simulated sensitivity (switch it on
   at the registry's guess, take the change of the channels and their
   derivatives in its parameters, regress the residual on them).
3. Trial-refit the :data:`TOP_K` best, keep the one that lowers the cost
   most, and add it if the relative improvement is at least
   :data:`THRESHOLD` (and the mean NMSE falls by at least :data:`MIN_GAIN`
   percentage points; polished, also against the base model polished alike, both refitted
   until they converge, the base model also from a fit on a shorter horizon first, the
   candidate too where that start takes it below the bar; before an effect is named a trial
   within :data:`NEAR` of the threshold is judged polished), and, when a validation record
   is given, if it also lowers the validation NMSE by :data:`VALIDATION_GAIN` per channel
   and its mean (against that control where it fits the training record better). Repeat
   until no candidate passes; then say that nothing (more) is missing rather than invent
   an effect.

NMSE (seed 002, percent) is reported before (base model fitted), after each
step and on a validation record when one is given.

The comparison is short-horizon prediction: the model is brought back to the record every
horizon (its slow drift from the measured motor angle removed while the joint moves,
the measured rest state in pauses; :mod:`.restarts`), chosen per record with the fitted
base model (:meth:`.problem.Problem.choose_horizon`)
and again (never longer) after each effect added; when the base model shows nothing, the
longer horizons on which it drifts and the shortest one are searched too (:func:`.search.escalate`).
Only effects the record can show are candidates (each effect's :class:`.effect.Condition`
list); the rest are listed as untestable with what the record lacks. The outcome is one of
*named*, *nothing missing* (residual at the noise level, and the base model carries over
to the validation record: :func:`.outcome.carry_gap`) or *unexplained*; for unexplained
residuals and untestable effects the diagnosis names the protocols (``hdgym experiment ...``)
whose records would decide (:func:`.outcome.judge`; a validation record that shows nothing
above its noise does not judge, :func:`.outcome.judged_record`, and is set aside before the
search). A search that names nothing and leaves the residual unexplained runs again with
every candidate trial-refitted, then with the two records' roles swapped; one that finds
nothing missing must find it with the roles swapped too (:func:`diagnose`).
"""

from __future__ import annotations

import time as _time
from dataclasses import replace

from hdgym.params import JointParams
from hdgym.progress import bar, step
from hdgym.record import Record

from . import residuals as R
from .diagnosis import Diagnosis, Step
from .fitting import FitResult, fit, rescored
from .floor import CURVE_SHARE
from .outcome import (
    judge,
    judged_record,
    mean_floor,
    noise_hidden,
    partial_evidence,
    resolved,
)
from .paths import get_value
from .pooled import pooled_candidate, pooled_words
from .problem import HORIZONS, Problem
from .ranking import _weighted
from .registry import REGISTRY, model_params
from .search import (
    ESCALATED_GAIN,
    MIN_GAIN,
    MIN_SCORE,
    NEAR,
    THRESHOLD,
    VALIDATION_GAIN,
    escalate,
    search_round,
)
from .settle import converge_named, settle, settle_named
from .spring_search import search_view, views

MAX_STEPS = 4
FIRST_HORIZON = 0.1
"""Prediction horizon, s, of the base fit before the record's own is chosen (the shortest
of :data:`.problem.HORIZONS`)."""
SPRING_TRIAL = 3
"""Trial refits on the spring curve (a staircase in the parameters: quantized motor angle
over torque bins) get this many times the trial budget. (Hold-out
wave-drive-50 / nonlinear_stiffness, locked, seed 62: with the time channels' budget the
knee stopped at 3.5 x the true one, the validation cut at 35 %; with 3 x, 1.5 x and 93 %.)"""
FIT_WINDOW = 5.0
"""Seconds of a long record the fits and the ranking use (the cost of a diagnosis)."""


def _choose_horizon(problem: Problem, vprob: Problem | None, p: JointParams,
                    horizons: tuple[float, ...] = HORIZONS) -> None:
    """Choose the training problem's horizon with ``p``; the validation problem follows."""
    problem.choose_horizon(p, horizons)
    if vprob is not None:
        vprob.segment = problem.segment


def diagnose(record: Record, params: JointParams, validate: Record | None = None, *,
             mode: str = "auto", threshold: float = THRESHOLD, max_steps: int = MAX_STEPS,
             quick: bool = False, cutoff: float | None = None,
             segment: float | str | None = "auto",
             fit_window: float | None = FIT_WINDOW) -> Diagnosis:
    """Compare ``params`` with ``record``, find, name and add the missing effects.

    The search runs on ``record`` and every effect it names must carry over to
    ``validate`` (:func:`_one_way`). When it names nothing and finds nothing missing, the
    search runs once more with the records' roles swapped, and nothing missing must hold
    there too (:func:`_nothing_missing_both_ways`). When it names nothing and the outcome
    is *unexplained*, it runs twice more, at the same bars, until one names an effect:

    * on the same records with every candidate trial-refitted, not only those that explain
      :data:`.search.MIN_SCORE` of the residual in a linearized refit (linearized at the
      registry's guess, the ranking can credit an effect with little of what its full
      trial refit removes);
    * with the two records' roles swapped: fitted and searched on ``validate``, each effect
      checked on ``record``. A record can show an effect the other hardly shows (a
      load-dependent friction a sine's load barely moves on one run and plainly on the
      other), and which of two runs a user calls the training record is arbitrary.

    The diagnosis that names an effect is returned (with the roles swapped its ``source``
    is ``validate``), else the first one with what the others read in its conclusion.
    Measured on development cases that read *unexplained* with nothing named (seeds
    110-230): with the roles swapped, the hidden effect was named on two of eight
    (wave-drive-50 / viscous_friction / step and tuttle-joint2 / load_dependent_friction /
    sine, seed 230, gap cut >= 80 %) and nothing on the other six, the two with nothing
    hidden among them; with every candidate trial-refitted, on one of four (hduc20 /
    position_dependent_friction / sine:2.49:0.5, seed 218: 2.65 -> 0.075 %, the truth
    0.009 %).

    Args:
        record: the measured run.
        params: the base model (its ``effects`` are the ones assumed present).
        validate: a second record of the same drive: NMSE is reported on it, every effect
            named must carry over to it, and it is searched in turn when the search on
            ``record`` leaves the residual unexplained.
        mode: ``simulate``, ``inverse`` or ``auto`` (see :class:`.fitting.Problem`).
        threshold: least relative cost reduction for adding an effect.
        max_steps: most effects added.
        quick: fewer least-squares iterations.
        cutoff: filter cutoff, Hz (default a twentieth of the sample rate).
        segment: prediction horizon, s: the multiple-shooting segment length (see
            :class:`.problem.Problem`); ``"auto"`` chooses it from the record
            (:meth:`.problem.Problem.choose_horizon`).
        fit_window: fit and rank on the first this many seconds of a longer record
            (time is what a diagnosis costs); NMSE is then also reported on the whole
            record (``nmse_record_before`` / ``_after``). None: use it all.
    """
    t0 = _time.perf_counter()
    kw = dict(mode=mode, threshold=threshold, max_steps=max_steps, quick=quick,
              cutoff=cutoff, segment=segment, fit_window=fit_window)
    first = _one_way(record, params, validate, **kw)
    if validate is None or first.validation is None or first.steps:
        return first
    if first.outcome == "nothing missing":
        return _nothing_missing_both_ways(first, record, params, validate, t0, kw)
    if first.outcome != "unexplained":
        return first
    tried = []
    for searched, checked, gate, how in (
            (record, validate, 0.0, "every candidate trial-refitted"),
            (validate, record, MIN_SCORE, SWAPPED)):
        again, where = _search_again(searched, checked, params, kw, how, gate)
        if again.steps:
            return _named_again(again, t0, record, "nothing was named and the residual "
                                "stayed unexplained", where)
        tried.append(f"again with {where} it reads {again.outcome}")
    return replace(first, seconds=_time.perf_counter() - t0,
                   conclusion="; ".join([first.conclusion, *tried]))


SWAPPED = "the records' roles swapped"
"""How :func:`diagnose` names its search with the two records' roles swapped."""


def _search_again(searched: Record, checked: Record, params: JointParams, kw: dict, how: str,
                  min_score: float = MIN_SCORE) -> tuple[Diagnosis, str]:
    """Another one-way search of :func:`diagnose` (``how`` names it in its progress bar and
    the conclusion): its diagnosis, and where it searched and checked, in words."""
    again = _one_way(searched, params, checked, **kw, min_score=min_score,
                     desc=f"diagnose again, {how}", pooled=False)
    return again, f"{how} (searched on {searched.source}, checked on {checked.source})"


def _named_again(again: Diagnosis, t0: float, record: Record, first: str,
                 where: str) -> Diagnosis:
    """A later search's diagnosis that named an effect, its conclusion saying what the
    first search on ``record`` read (``first``) and where the later one searched."""
    return replace(again, seconds=_time.perf_counter() - t0, conclusion=(
        f"searched on {record.source}, {first}; again with {where}: " + again.conclusion))


def _nothing_missing_both_ways(first: Diagnosis, record: Record, params: JointParams,
                               validate: Record, t0: float, kw: dict) -> Diagnosis:
    """*Nothing missing* holds only when the search with the records' roles swapped (fitted
    and searched on ``validate``, checked on ``record``) finds nothing missing too: which
    run a user calls the training record is arbitrary, and the base fit on one can take up
    an effect the other shows (fresh seed 278, hdf40 / stribeck_friction / sine:4.66:2:
    0.017 % against the generating joint's 0.0053 %, within 3 x the noise NMSE; swapped,
    Stribeck friction cut the cost by 18.7 % against the converged base model and the
    outcome read *unexplained*). An effect the swapped search names is returned (as after
    an unexplained first search); an *unexplained* swapped outcome makes the first one
    *unexplained*, with the swapped search's next experiments. Ten development and blind
    cases with nothing present read *nothing missing* both ways."""
    again, where = _search_again(validate, record, params, kw, SWAPPED)
    if again.steps:
        return _named_again(again, t0, record, "nothing was missing", where)
    conclusion = f"{first.conclusion}; again with {where} it reads {again.outcome}"
    if again.outcome == "nothing missing":
        return replace(first, seconds=_time.perf_counter() - t0, conclusion=conclusion)
    return replace(first, seconds=_time.perf_counter() - t0, conclusion=conclusion,
                   outcome="unexplained", next_experiments=list(dict.fromkeys(
                       first.next_experiments + again.next_experiments)),
                   unexplained_channels={**first.unexplained_channels,
                                         "swapped": f"with {where}: {again.outcome}"})


def _one_way(record: Record, params: JointParams, validate: Record | None, *,
             mode: str, threshold: float, max_steps: int, quick: bool, cutoff: float | None,
             segment: float | str | None, fit_window: float | None,
             min_score: float = MIN_SCORE, desc: str = "diagnose",
             pooled: bool = True) -> Diagnosis:
    """:func:`diagnose` with ``record`` searched and ``validate`` the check (arguments as
    there; ``min_score``: the least share of the residual a linearized refit must explain
    for any trial refit, :func:`.search.search_round`; ``desc``: the progress bar's
    label; ``pooled``: with nothing named and the validation residual not resolved, the
    candidates whose trial refit reached half the training record's bar are judged on both
    records fitted together, :func:`.pooled.pooled_candidate`; the later searches of
    :func:`diagnose` skip it, the first one ran it on the same two records)."""
    t0 = _time.perf_counter()
    full = None
    if fit_window and record.duration > fit_window * 1.001:
        full = record
        record = record.slice(None, float(record.time[0]) + fit_window)
    auto = segment == "auto"
    problem = Problem(record, params, mode=mode, cutoff=cutoff,
                      segment=FIRST_HORIZON if auto else segment)
    vprob = (Problem(validate, params, mode=problem.mode, cutoff=cutoff, channels=problem.names,
                     segment=problem.segment)
             if validate is not None else None)
    # a validation record that shows nothing above its noise judges nothing: not the
    # search's carry-over check (which it could never pass), the refit on both records,
    # nor the outcome; decided once, here
    judged, why_judged = judged_record(problem, vprob)
    if judged is problem:
        vprob = None
    nfev_base, nfev_trial, nfev_polish = (20, 10, 20) if quick else (40, 15, 30)
    why = {n: e.why_not(problem.scales) for n, e in REGISTRY.items()}
    untestable_why = {n: w for n, w in why.items() if w is not None}
    untestable = list(untestable_why)

    prog = bar(total=max_steps + 1, desc=desc, unit="fit")
    given = problem.nmse(params)
    base_fps = model_params(params, problem.scales, params)
    base_paths = [fp.path for fp in base_fps]
    before = fit(problem, params, base_fps, max_nfev=nfev_base)
    if auto and not problem.inverse:
        # the horizon: chosen with the fitted base model (a given model that is some per
        # cent off drifts on any long horizon; the fitted one only where the record does)
        _choose_horizon(problem, vprob, before.params)
        before = rescored(problem, before)
    current = before
    chosen = problem.segment
    prog.update(1)
    steps: list[Step] = []
    spring_stuck: dict[str, str] = {}
    conclusion, alone = "", None  # alone: settle's training NMSE, judged against validation
    candidates: list[dict] = []
    seen: list[dict] = []  # candidates of the escalated horizons
    for _ in range(max_steps):
        prog.set_postfix_str(f"{len(steps)} effect(s) added", refresh=False)
        # control refit: the same iteration budget without a new effect, so a candidate is
        # credited only with what the effect adds, not with a longer optimization
        control = fit(problem, current.params,
                      model_params(current.params, problem.scales, params), max_nfev=nfev_trial)
        if control.cost < current.cost:
            current = FitResult(control.params, {**current.values, **control.values},
                                control.nmse, control.nfev, control.cost)
            if not steps:
                before = current
        escalated = False
        accepted, reason, candidates = search_round(problem, vprob, current, params,
                                                    base_paths, threshold, nfev_trial,
                                                    nfev_polish, near=1.0 if steps else NEAR,
                                                    min_score=min_score)
        if accepted is None and auto and not problem.inverse and not steps:
            # nothing at the chosen horizon: an effect that acts over longer stretches (a
            # friction ripple over an output turn, a slow speed change) shows as the drift
            # that made the short horizon the choice; look where the current model drifts
            found = escalate(problem, vprob, current, params, base_paths, threshold,
                             nfev_trial, nfev_polish, seen, min_score)
            if found is not None:
                accepted, candidates, current = found
                escalated = True
        for view in views(problem, current.params) if accepted is None and auto and not steps \
                else ():  # then the spring curve (locked output) or the line channels
            n_view = SPRING_TRIAL * nfev_trial if view == "spring" else nfev_trial
            found_s, cands_s, on_curve, spring_stuck = search_view(
                problem, vprob, current, params, nfev_trial, CURVE_SHARE,
                lambda cur, n=n_view: search_round(problem, vprob, cur, params, base_paths,
                                                   threshold, n, nfev_polish, ESCALATED_GAIN,
                                                   True, min_score=min_score),
                view, nfev_base)
            untestable_why = {n: w for n, w in untestable_why.items()  # compared on the view
                              if not REGISTRY[n].testable(problem.view_scales(view))}
            if found_s is not None:
                accepted, candidates, current, before = found_s, cands_s, on_curve, on_curve
                escalated = True
        if accepted is None:
            conclusion = reason
            break
        best, polished, rel = accepted
        steps.append(_step(problem, vprob, current, best, polished, rel, candidates))
        current = polished
        if auto and not problem.inverse and not escalated:
            # the horizon again, with the model that now has the effect: the base model may
            # have needed a short one (or allowed a long one) only because it lacked it
            # (only shorter: a longer one is taken only where an effect removes the drift,
            # see _escalate; not right after that, the horizon was chosen where it shows)
            h_prev = problem.segment
            _choose_horizon(problem, vprob, current.params,
                            tuple(h for h in HORIZONS if h <= h_prev))
            if problem.segment != h_prev:
                current = rescored(problem, current)
        prog.update(1)
    else:
        conclusion = f"stopped after {max_steps} effects (the most one diagnosis adds)"
    if not steps:
        # a candidate that passed every check but the escalated cut explains part of the
        # residual: no refit on both records may then call the rest slack
        partly = [c["name"] for c in seen + candidates if "escalated_cut" in c]
        current, conclusion, alone = settle(problem, vprob, current, params, nfev_base, auto,
                                            conclusion, _choose_horizon, both=not partly)
        before = current
        if (pooled and vprob is not None and problem.compare == "time"
                and not resolved(False, vprob.nmse(current.params)["mean"],
                                 vprob.noise["mean"], mean_floor(vprob, current.params))):
            # what came near the training record's bar, judged on both records fitted together
            prog.set_postfix_str("candidates refitted on both records")
            found_p = pooled_candidate(problem, vprob, current, params, base_paths, candidates,
                                       threshold, MIN_GAIN, VALIDATION_GAIN, nfev_polish)
            if found_p is not None:
                cand, named, before, rel, why = found_p
                steps.append(_step(problem, vprob, before, cand, named, rel, candidates))
                current = named
                conclusion += "; named on both records: " + why
            else:
                conclusion += pooled_words(candidates)
    prog.close()
    if (before.nmse is not None and problem.segment != chosen
            and problem.compare == "time"):  # escalated: report on it
        before = rescored(problem, before)
    if steps and not conclusion.startswith("stopped"):
        conclusion = (f"found {', '.join(s.name for s in steps)}; then " + conclusion)
    conclusion += why_judged
    untestable_why = noise_hidden(candidates, problem.noise["mean"], untestable_why)
    untestable = list(untestable_why)
    both = None
    if steps:  # the final refits take minutes on some records: a bar of their own
        with bar(total=2, desc=f"{desc}: final refits", unit="fit") as fin:
            # the polish after each effect had one fit's budget: the named model, converged
            refit = converge_named(problem, vprob, current, params, nfev_base)
            if refit is not None:
                conclusion += (f"; the final model refitted until it converged: NMSE "
                               f"{current.nmse['mean']:.3g} -> {refit.nmse['mean']:.3g} %")
                current = refit
            step(fin, "on both records")
            both = settle_named(problem, vprob, current, before, params, nfev_base,
                                VALIDATION_GAIN)
            fin.update(1)
    if both is not None:  # validation NMSE before and after, each from a fit that saw it
        current, before, words = both
        conclusion += words
    where_before = _where(problem, before.params)
    evidence = {} if steps else partial_evidence(seen + candidates, untestable_why)
    outcome, nexts, stuck, floor = judge(
        judged, current.params, model_params(current.params, judged.scales, params), steps,
        candidates, untestable_why, params, {**spring_stuck, **evidence}, alone,
        base=before.params)
    if stuck:
        conclusion += ("; what remains is not noise on " + "; ".join(stuck.values()))
    # the whole record, compared once for both fits (building the comparison, its noise
    # estimate included, costs about 1.5 s on a 60 s record)
    whole = None if full is None else problem.like(full, params)
    return Diagnosis(
        source=record.source, mode=problem.mode, channels=problem.names,
        base_effects=tuple(params.effects), nmse_given=given, before=before, steps=steps,
        after=current, where_before=where_before, where_after=_where(problem, current.params),
        final_candidates=candidates, conclusion=conclusion,
        nmse_given_validation=_validate_nmse(vprob, params),
        nmse_before_validation=_validate_nmse(vprob, before.params),
        nmse_after_validation=_validate_nmse(vprob, current.params),
        validation_source=None if validate is None else validate.source,
        untestable=untestable, untestable_why=untestable_why, outcome=outcome,
        unexplained_channels=stuck, compare=problem.compare,
        horizon=None if problem.inverse else problem.segment,
        noise=judged.noise, floor=floor, next_experiments=nexts,
        seconds=_time.perf_counter() - t0, problem=problem,
        validation=vprob, fit_window=None if full is None else fit_window,
        nmse_record_before=None if whole is None else whole.nmse(before.params),
        nmse_record_after=None if whole is None else whole.nmse(current.params))


def _step(problem: Problem, vprob: Problem | None, current: FitResult, best: dict,
          polished: FitResult, rel: float, candidates: list[dict]) -> Step:
    """The :class:`.diagnosis.Step` of candidate ``best`` named with the fit ``polished``
    (``rel``: its relative cut of the cost), from the model ``current``."""
    eff = REGISTRY[best["name"]]
    values = {fp.path: get_value(polished.params, fp.path)
              for fp in eff.fit_params(polished.params, problem.scales)}
    for path in [k for k in values if k.endswith(".sin")]:  # also as amplitude and phase
        item = path[: -len(".sin")]
        values[item + ".amplitude"] = get_value(polished.params, item + ".amplitude")
        values[item + ".phase"] = get_value(polished.params, item + ".phase")
        values[item + ".order"] = get_value(polished.params, item + ".order")
        if item.startswith("kinematic_error."):  # the line's order of the WG angle
            h = polished.params.kinematic_error.harmonics[int(item.split("[")[1][:-1])]
            values[item + ".wg_order"] = (
                h.order * polished.params.transmission.port_factor(h.port))
    evidence = {"signature": best["signature"], "detail": best["detail"],
                "signature_explained": best["signature_explained"],
                "sensitivity_explained": best["sensitivity_explained"],
                "relative_improvement": round(rel, 4)}
    return Step(best["name"], evidence, values, polished.nmse,
                _validate_nmse(vprob, polished.params),
                (current.cost - polished.cost) / current.cost, candidates, polished.params)


def _validate_nmse(vp: Problem | None, p: JointParams) -> dict[str, float] | None:
    return None if vp is None else vp.nmse(p)


def _where(problem: Problem, p: JointParams) -> dict:
    if problem.compare == "lines":  # coefficients, not samples: nothing to localize in time
        return {}
    res = problem.residuals(p)
    _, w = _weighted(problem, res)
    return R.localize(res, w, problem.masked_context())
