"""The honest outcome of a diagnosis and the experiments that would decide the rest."""

from __future__ import annotations

import math

import numpy as np

from hdgym.params import JointParams

from .effect import FitParam, Scales
from .floor import floor_nmse, unexplained_channels
from .problem import Problem
from .registry import REGISTRY, lacking

RESOLVED = 0.5
"""NMSE, percent, at or below which a residual counts as resolved when no effect is named:
what complete base models reach on the tuned nothing-hidden cases (fit slack, restarts)."""
NOISE_FACTOR = 3.0
"""A residual within this factor of the measurement-noise NMSE is at the noise level."""


FLOOR_FACTOR = 2.0
"""A model with an effect named is at its floor when its final mean NMSE is within this
factor of its own comparison floor (:func:`.floor.floor_nmse`, mean over channels): a model
that is exactly right differs from that estimate by another noise realization and its
restarts, well within a factor 2 (measured on generated cases, :mod:`.truth`); a residual
beyond it is something the named model still lacks, or fit slack."""


BLIND = 100.0
"""Mean measurement-noise NMSE, percent, at or above which a validation record cannot judge
the outcome (:func:`judged_record`)."""
CARRY_FACTOR = 10.0
"""With nothing named, a validation NMSE more than this factor above what the base model
reaches on the training record alone is a base model that does not carry over, not one
that lacks nothing (:func:`carry_gap`)."""


def carry_gap(final: float, alone: float | None, noise: float) -> str | None:
    """Why a base model whose validation residual ``final`` (mean NMSE, percent, after the
    refit on both records) looks resolved still lacks something, or None.

    ``alone``: the training record's mean NMSE of the base model fitted on it alone;
    ``noise``: the validation record's measurement-noise NMSE. A model that lacks nothing
    fits both records about as well as either (the nothing-hidden cases: 1.6-1.9 x). When
    the validation residual stays more than :data:`CARRY_FACTOR` x above the training
    one, with one setting fitted to both, the setting that fits the training record is
    mimicking something the other record shows otherwise (hold-out hduc20 /
    nonlinear_stiffness, locked, seed 74: 0.0027 % alone, 0.433 % on validation; hdf40 /
    stribeck_friction: 0.0213 % against 0.323 %). Not below the noise level
    (:data:`NOISE_FACTOR`): a validation record at its noise says nothing.
    """
    if alone is None or not math.isfinite(alone) or final <= NOISE_FACTOR * noise:
        return None
    if final <= CARRY_FACTOR * max(alone, 0.0):
        return None
    return (f"validation: NMSE {final:.3g} % with the base model refitted on both records, "
            f"{final / max(alone, 1e-12):.3g} x the {alone:.2g} % it reaches on the training "
            f"record alone: no setting of its own parameters carries over")


def partial_evidence(candidates: list[dict], untestable: dict[str, str] | None = None
                     ) -> dict[str, str]:
    """What the candidates tried say against *nothing missing*: ``{"candidate:<name>": why}``
    for each whose polish cut the training cost against the base model refitted until it
    converged (``partial_cut``, :func:`.search.search_round`) by at least the validation gain
    and carried over to the validation record, yet fell short of naming it. A residual
    that an effect explains a real part of is not fit slack, though the base fit takes
    it to within :data:`RESOLVED` (development seed 170, hdf40 / stribeck_friction /
    sine:5.63:1: Stribeck friction cut the cost by 18.5 % against the converged base
    model, and 0.142 % read "nothing missing" where the joint that made the record shows
    0.019 %). It is the evidence a named effect must give (a cut against the converged base
    that carries over), at the validation gain's bar instead of the naming threshold.

    Not from a candidate ``untestable`` lists (:func:`noise_hidden`: at the size the record
    suggests it would change the channels by less than their noise; its cut is then the
    slack its many parameters take up, not its own: development seed 398, wave-drive-50 /
    none / sine:0.427:0.5, position-dependent friction's two ripple lines per side cut the
    training cost by 14.9 % at a suggested 0.0069 % NMSE against 0.013 % noise, and the
    case read *unexplained* with nothing hidden)."""
    out = {}
    for c in candidates:
        if c["name"] in (untestable or {}):
            continue
        if "partial_cut" in c and f"candidate:{c['name']}" not in out:
            out[f"candidate:{c['name']}"] = (
                f"{c['name']}: it cut the training cost by {100 * c['partial_cut']:.3g} % "
                f"against the base model refitted until it converged and carried over to the "
                f"validation record, short of what names it: part of the residual is likely "
                f"its")
    return out


def judged_record(problem: Problem, vprob: Problem | None) -> tuple[Problem, str]:
    """The record the outcome is judged on (the validation record when there is one), and
    the words for the conclusion when it is not the one given.

    A validation record whose compared channels stand nowhere above their measurement
    noise (mean noise NMSE at least :data:`BLIND`: a joint that never breaks away leaves
    the torsion and torque channels with no variance of their own) would call any residual
    noise: the outcome is then judged on the training record (hold-out tuttle-joint3 /
    position_dependent_friction / step:0.262, seed 74: the validation step did not turn the
    joint, its noise NMSE was 10^229 %, and 33 % read "nothing missing" while the training
    record's lines showed the ripple at 100 x their noise).
    """
    if vprob is None:
        return problem, ""
    if vprob.noise["mean"] >= BLIND:
        return problem, (f"; the validation record shows nothing above its measurement noise "
                         f"(mean noise NMSE above {BLIND:g} %): judged on the training record")
    return vprob, ""


def noise_hidden(candidates: list[dict], noise: float,
                 untestable_why: dict[str, str]) -> dict[str, str]:
    """``untestable_why`` with the candidates that the record's noise would hide at the
    size the record suggests (``size_nmse``, percent, below the mean noise NMSE ``noise``)."""
    out = dict(untestable_why)
    for c in candidates:
        if c.get("size_nmse", math.nan) < noise and c["name"] not in out:
            out[c["name"]] = (f"at the size this record suggests it changes the compared "
                              f"channels by {c['size_nmse']:.2g} % NMSE, below their "
                              f"measurement noise ({noise:.2g} %)")
    return out


def at_floor(final: float, floor: float) -> bool:
    """Whether a mean NMSE ``final`` (percent) is at the comparison floor ``floor``
    (:data:`FLOOR_FACTOR`)."""
    return final <= FLOOR_FACTOR * floor


def mean_floor(problem: Problem, p: JointParams) -> float | None:
    """The mean over channels of :func:`.floor.floor_nmse` (percent; None when it cannot be
    measured: an inverse comparison, a diverging run)."""
    return _channel_mean(floor_nmse(problem, p))


def _channel_mean(per_channel: dict[str, float]) -> float | None:
    """The mean of a per-channel floor (None for an empty one)."""
    return float(np.mean(list(per_channel.values()))) if per_channel else None


def at_noise_level(final: float, noise: float) -> bool:
    """Whether a mean NMSE ``final`` (percent) counts as resolved against the mean
    measurement-noise NMSE ``noise`` (:data:`NOISE_FACTOR`, :data:`RESOLVED`)."""
    return final <= max(NOISE_FACTOR * noise, RESOLVED)


def noisy_channel_hides(final: dict[str, float], noise: dict[str, float]) -> dict[str, str]:
    """Channels whose own residual is neither at their own noise level nor resolved, though
    the mean over channels may be: channel -> why.

    The mean NMSE is judged against the mean noise NMSE (:func:`at_noise_level`); one noisy
    channel (a torque sensor's noise against a small torque) then lends its allowance to the
    others. A channel counts as resolved when its NMSE is within :data:`NOISE_FACTOR` x its
    own noise NMSE or at most :data:`RESOLVED` (the development case tuttle-joint2 /
    stribeck_friction / sine:1.75:1, seed 110: torque noise 3.9 % made the mean noise
    0.99 %, and 0.99 % read "nothing missing" with the transmission error at 0.57 %, 62 x
    its noise, and the motor speed at 3,700 x its own).
    """
    out = {}
    for k, v in final.items():
        if k == "mean" or k not in noise or not math.isfinite(v):
            continue
        if not at_noise_level(v, noise[k]):
            out[k] = (f"NMSE {v:.3g} % against its own measurement noise {noise[k]:.2g} % (the "
                      f"mean is within {NOISE_FACTOR:g} x the mean noise, this channel is not)")
    return out


def resolved(named: bool, final: float, noise: float, floor: float | None,
             untested_only: bool = False) -> bool:
    """Whether a final mean NMSE ``final`` (percent) is resolved. With an effect named: at
    the final model's own floor (:func:`at_floor`). With nothing named (or no floor): at
    the noise level, :data:`NOISE_FACTOR` x the measurement-noise NMSE ``noise``, or
    within :data:`RESOLVED` and, where the floor is known, at the base model's floor too,
    unless ``untested_only``: every effect the model lacks is one the record cannot show
    (listed as untestable, with the experiment that would), so within :data:`RESOLVED`
    the residual can only be fit slack as far as this record can tell (development seed
    290, tuttle-joint1 / none / sine:1.9:2: nothing the record can test was left out, and
    the base model refitted on both records left 0.0281 %, 3.7 x its floor and 3.2 x what
    the joint that made the records leaves; read *unexplained*, searched again with the
    roles swapped *nothing missing*).

    :data:`RESOLVED` allows for a base fit's slack above the noise level; a residual more
    than :data:`FLOOR_FACTOR` x what the model leaves on a record it made itself is not
    that: development seed 266, hduc20 / stiction / sine:1.76:1 read "nothing missing" at
    0.024 % (noise 0.00042 %, floor 0.00097 %), tuttle-joint1 /
    position_dependent_friction / sine:2.16:2 at 0.134 % (noise 0.031 %, floor 0.0115 %;
    now 0.0725 %, within 3 x the noise, and the effect untestable on that record).
    The floor alone would judge more: complete base models fitted to within 0.1 % of every
    parameter stand up to 11 x their floor where the record is that sensitive (tuned case
    none (current steps), 3 s in --quick: 0.0023 % against 0.0002 %, the noise NMSE
    0.0024 %), while a small effect can hide at 5 x (seed 266, wave-drive-50 / stiction /
    random:0.165:4: 0.198 % against 0.038 %, noise 0.148 %, still "nothing missing"). And
    the floor of a base model that lacks an effect is no floor for the record: without the
    effect's damping or friction its own record can show more than the true joint's (the
    hold-out case tuttle-joint3 / viscous_friction / sine:0.209:2, seed 26: base fit
    0.932 %, its floor 0.836 %, the generating joint 0.387 %)."""
    known = floor is not None and math.isfinite(floor)
    if named and known:
        return at_floor(final, floor)
    if final <= NOISE_FACTOR * noise:
        return True
    return final <= RESOLVED and (not known or untested_only or at_floor(final, floor))


def _lacked(p: JointParams, scales: Scales | None) -> list[str]:
    """The effects ``p`` lacks: :func:`.registry.lacking` on the record's ``scales``, or by
    the switch alone without them."""
    return lacking(p, scales) if scales is not None else [n for n in REGISTRY
                                                          if n not in p.effects]


def lacks_only_untestable(p: JointParams, untestable_why: dict[str, str],
                          scales: Scales | None = None) -> bool:
    """Whether every effect of the registry that ``p`` lacks (:func:`_lacked`) is
    untestable on the record (a key of ``untestable_why``): nothing the record can show is
    left to name."""
    return all(n in untestable_why for n in _lacked(p, scales))


def outcome_of(steps: list, final: float, noise: float, candidates: list[dict],
               untestable_why: dict[str, str], given: JointParams,
               channels_unexplained: dict[str, str] | None = None,
               floor: float | None = None, untested_only: bool = False, *,
               scales: Scales | None = None) -> tuple[str, list[str]]:
    """The honest outcome and the experiments that would decide what this record cannot.

    Args:
        steps: the effects added; final: the final NMSE, percent (validation record when
        there is one); noise: its measurement-noise NMSE, percent; candidates: the last
        ranking; untestable_why: effect -> what the record lacks; given: the base model;
        channels_unexplained: channels whose own residual is neither noise nor fit slack
        (:func:`.floor.unexplained_channels`; channel -> why); floor: the final model's
        comparison floor, mean NMSE percent (:func:`.floor.floor_nmse`; None: unknown);
        untested_only: every effect the model lacks is untestable on the record
        (:func:`resolved`); scales: the record's, to tell what the base model lacks
        (:func:`_lacked`).

    *named* when an effect was added (each had to cut the gap) and what remains is at the
    final model's own floor (:func:`at_floor`; without a floor, at the noise level as
    below), else *named; rest unexplained*; with nothing added, *nothing missing* when the
    final NMSE is at the noise level (:data:`NOISE_FACTOR` x the measurement-noise NMSE) or
    resolved (:data:`RESOLVED`: fit slack and restarts keep complete base fits above it)
    and at the base model's own floor (:func:`resolved`), else *unexplained*. Either way no
    channel on its own may be unexplained (a clipped current is a few per cent of its
    channel and nothing on the others, below the mean's level). *named; rest unexplained*:
    the gap shrank, but what remains is not at the floor and no further candidate explains
    it. The next experiments: the identification protocol of every untestable effect that is
    not in the model, and, for an unexplained residual, of the two best-ranked candidates.
    """
    done = (resolved(bool(steps), final, noise, floor, untested_only)
            and not channels_unexplained)
    if steps:
        outcome = "named" if done else "named; rest unexplained"
    elif done:
        outcome = "nothing missing"
    else:
        outcome = "unexplained"
    lacked = _lacked(given, scales)
    names = [n for n in untestable_why if n in lacked]
    if outcome.endswith("unexplained"):
        names = [c["name"] for c in candidates[:2]] + names
    protocols = list(dict.fromkeys(REGISTRY[n].protocol for n in names if REGISTRY[n].protocol))
    return outcome, [f"hdgym experiment {p}" for p in protocols]


def judge(judged: Problem, p: JointParams, fps: list[FitParam], steps: list, candidates: list[dict],
          untestable_why: dict[str, str], given: JointParams, stuck: dict[str, str],
          alone: float | None = None, base: JointParams | None = None
          ) -> tuple[str, list[str], dict[str, str], float | None]:
    """The outcome of a diagnosis whose final model ``p`` is judged on ``judged``.

    The final model's comparison floor (:func:`.floor.floor_nmse`, mean over channels) is
    measured; when the mean NMSE is resolved (at that floor with an effect named, at the noise
    level without), each channel is also checked on its own
    (:func:`.floor.unexplained_channels`, added to ``stuck``), and with nothing named the
    validation residual against the training record's alone (``alone``: that mean NMSE,
    percent; :func:`carry_gap`). With an effect named, the floor the mean is judged against
    is the lower of the named model's and the base model's ``base`` (the model before the
    effects, as reported): a named model fitted into a setting whose own record compares
    noisily raises its own floor, and would read as at it (development seed 398,
    tuttle-joint1 / stiction / random:1.75:2: stiction named, validation NMSE 0.0229 %,
    the named model's floor 0.0305 %, the base model's 0.0060 %, the joint that made the
    records 0.0052 %: the rest is not at a floor). Returns ``(outcome, next
    experiments, unexplained channels, floor)`` (:func:`outcome_of`; floor None when it
    cannot be measured: an inverse comparison, a diverging run).
    """
    final_channels = judged.nmse(p)
    final = final_channels["mean"]
    fl = floor_nmse(judged, p)
    floor = _channel_mean(fl)  # mean_floor, with the channels kept for the checks below
    if steps and base is not None and floor is not None:
        other = mean_floor(judged, base)
        floor = floor if other is None else min(floor, other)
    stuck = dict(stuck)
    untested_only = lacks_only_untestable(p, untestable_why, judged.scales)
    # the mean can hide one channel that alone shows what the model lacks
    if resolved(bool(steps), final, judged.noise["mean"], floor, untested_only):
        stuck |= unexplained_channels(judged, p, fps, final_channels, NOISE_FACTOR, fl)
        if not steps:
            stuck |= {k: v for k, v in noisy_channel_hides(final_channels, judged.noise).items()
                      if k not in stuck}
        gap = None if steps else carry_gap(final, alone, judged.noise["mean"])
        if gap is not None:
            stuck["validation"] = gap
    outcome, nexts = outcome_of(steps, final, judged.noise["mean"], candidates,
                                untestable_why, given, stuck, floor, untested_only,
                                scales=judged.scales)
    return outcome, nexts, stuck, floor


def carries_over(v_now: dict[str, float], v_new: dict[str, float], names: tuple[str, ...],
                 gain: float) -> tuple[bool, float]:
    """Whether an effect's refit carries over to the validation record: ``(passes, ratio)``.

    ``v_now``, ``v_new``: the validation record's NMSE per channel (and ``"mean"``), %,
    before and after the effect. ``ratio`` is the geometric mean over ``names`` of the
    channels' NMSE ratios (scale-free, so a channel with a tiny variance cannot decide
    alone); it must be at most ``1 - gain``, and the mean NMSE must fall too: the channel
    that carries the error may not get worse while the others improve (hold-out hduc20 /
    kinematic_error / sine:3.38:1, seed 38: the mean rose from 5.7 to 7.8 % at a
    per-channel factor of 0.72).
    """
    ratios = [v_new[k] / v_now[k] for k in names if v_now[k] > 0 and math.isfinite(v_now[k])]
    ratio = float(np.exp(np.mean(np.log(np.maximum(ratios, 1e-12))))) if ratios else 1.0
    return ratio <= 1.0 - gain and v_new["mean"] < v_now["mean"], ratio
