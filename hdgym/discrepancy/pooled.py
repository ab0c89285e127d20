"""An effect judged on the training and validation records fitted together.

The search (:func:`.search.search_round`) fits every candidate on the training record and
checks that it carries over to the validation record. When the training record pins the
base model's parameters poorly, the base fit moves into a valley that mimics the missing
effect there and the effect, refitted from that valley, carries over poorly: the search
names nothing although one setting of the base model plus the effect fits both records and
the base model alone fits neither. :func:`.settle.settle` already refits the base model on
both records before it would call the residual *unexplained*; :func:`pooled_candidate`
refits the candidates whose trial refit reached half the training record's bar
(:data:`POOLED_NEAR`) the same way, and names the one that cuts the cost of both records
together by the search's own threshold against that base refit and carries over record by
record.

Development seed 302, hdf40 / viscous_friction / sine:3.09:2 (a 0.31 % effect on the
training record, 3.4 % on the validation record, no torsion channel on the first): viscous
friction cut the training cost by 96.9 % and the validation NMSE only by a factor 0.96,
fitted the other way round 33 % against the converged base model (40 % names an effect).
Refitted on both records it cut their cost by 98.7 % against the base model refitted alike:
validation NMSE 0.117 -> 0.0017 %, the joint that made the records 0.0019 %. Two
development cases with stiction hidden that read *unexplained* stay so (wave-drive-50 /
stiction / random:0.283:4, seed 302: stiction's trial refit qualified, and refitted on both
records cut their cost by 13 %; hdf40 / stiction / sine:4.41:1, seed 290: no trial refit
qualified).
"""

from __future__ import annotations

from hdgym.params import JointParams

from .fitting import FitResult, rescored
from .outcome import carries_over
from .paths import reset_to
from .problem import Problem
from .ranking import _start
from .registry import model_params
from .settle import TwoRecords, converge

POOLED_TOP = 2
"""Candidates :func:`pooled_candidate` refits on both records (the best trial refits)."""
POOLED_NEAR = 0.5
"""A candidate is refitted on both records when its trial refit cut the training cost by
this share of the naming threshold (as :data:`.search.NEAR` polishes one)."""


def eligible(candidates: list[dict], threshold: float) -> list[dict]:
    """The trial-refitted candidates whose cut of the training cost reached
    :data:`POOLED_NEAR` x ``threshold``, best first, at most :data:`POOLED_TOP`."""
    tried = [c for c in candidates
             if c.get("relative_improvement", 0.0) >= POOLED_NEAR * threshold]
    tried.sort(key=lambda c: -c["relative_improvement"])
    return tried[:POOLED_TOP]


def pooled_candidate(problem: Problem, vprob: Problem, current: FitResult,
                     given: JointParams, base_paths: list[str], candidates: list[dict],
                     threshold: float, min_gain: float, gain: float, nfev: int
                     ) -> tuple[dict, FitResult, FitResult, float, str] | None:
    """The first of the :func:`eligible` candidates that earns its name on both records.

    The base model (``current``) and each candidate, switched on from it and from the base
    with its parameters back at their given values (:func:`.ranking._start`; the cheaper
    start on both records), are refitted on both records together until they converge
    (:func:`.settle.converge` on :class:`.settle.TwoRecords`, the coordinate search on a
    stick-slip record). A candidate passes when it cuts the joint cost by ``threshold``
    and the mean NMSE of both records by ``min_gain`` points against the base refit, and
    cuts each record's NMSE by ``gain`` (:func:`.outcome.carries_over`, geometric mean over
    the channels, and its mean). Returns ``(candidate, fit, base fit, relative cut, why)``,
    both fits' NMSE on the training record, or None (what each refit did is then in the
    candidate's ``"pooled"`` entry, :func:`pooled_words`).
    """
    cands = eligible(candidates, threshold)
    if not cands:
        return None
    two = TwoRecords(problem, vprob)
    base = converge(two, current.params, model_params(current.params, problem.scales, given),
                    nfev, search=True)
    at = two.nmse(current.params)  # (both records simulated once)
    if not base.cost < at["mean"] / 100:
        base = FitResult(current.params, current.values, at, 0, at["mean"] / 100)
    reset = reset_to(base.params, given, base_paths)
    parts = (problem, vprob)
    b_nm = [q.nmse(base.params) for q in parts]
    for cand in cands:
        starts = [_start(problem, base.params, cand["name"]),
                  _start(problem, reset, cand["name"])]
        start = min(starts, key=lambda s: two.nmse(s)["mean"])
        r = converge(two, start, model_params(start, problem.scales, given), nfev,
                     search=True)
        rel = (base.cost - r.cost) / base.cost if base.cost > 0 else 0.0
        drop = base.nmse["mean"] - r.nmse["mean"]
        each = [carries_over(b, q.nmse(r.params), q.names, gain) for b, q in zip(
            b_nm, parts, strict=True)]
        cand["pooled_cut"] = round(rel, 4)
        why = (f"{cand['name']} refitted on the training and validation records together "
               f"cuts their cost by {100 * rel:.1f} % against the base model refitted alike "
               f"(threshold {100 * threshold:.0f} %; NMSE factors per channel "
               f"{each[0][1]:.2f} on training, {each[1][1]:.2f} on validation, needs <= "
               f"{1 - gain:.2f} on each)")
        if rel >= threshold and drop >= min_gain and all(ok for ok, _ in each):
            return cand, rescored(problem, r), rescored(problem, base), rel, why
        cand["pooled"] = why
    return None


def pooled_words(candidates: list[dict]) -> str:
    """What :func:`pooled_candidate` found of the candidates it refitted and did not name,
    for the conclusion ("" when it refitted none)."""
    said = [c["pooled"] for c in candidates if "pooled" in c]
    return "; not named on both records: " + "; ".join(said) if said else ""
