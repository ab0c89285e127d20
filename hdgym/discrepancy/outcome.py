"""The honest outcome of a diagnosis and the experiments that would decide the rest."""

from __future__ import annotations

from hdgym.params import JointParams

from .registry import REGISTRY

RESOLVED = 0.5
"""NMSE, percent, at or below which a residual counts as resolved when no effect is named:
what complete base models reach on the tuned nothing-hidden cases (fit slack, restarts)."""
NOISE_FACTOR = 3.0
"""A residual within this factor of the measurement-noise NMSE is at the noise level."""


def at_noise_level(final: float, noise: float) -> bool:
    """Whether a mean NMSE ``final`` (percent) counts as resolved against the mean
    measurement-noise NMSE ``noise`` (:data:`NOISE_FACTOR`, :data:`RESOLVED`)."""
    return final <= max(NOISE_FACTOR * noise, RESOLVED)


def outcome_of(steps: list, final: float, noise: float, candidates: list[dict],
               untestable_why: dict[str, str], given: JointParams,
               channels_unexplained: dict[str, str] | None = None) -> tuple[str, list[str]]:
    """The honest outcome and the experiments that would decide what this record cannot.

    Args:
        steps: the effects added; final: the final NMSE, percent (validation record when
        there is one); noise: its measurement-noise NMSE, percent; candidates: the last
        ranking; untestable_why: effect -> what the record lacks; given: the base model;
        channels_unexplained: channels whose own residual is neither noise nor fit slack
        (:func:`.floor.unexplained_channels`; channel -> why).

    *named* when an effect was added (each had to cut the gap); else *nothing missing*
    when the final NMSE is at the noise level (:data:`NOISE_FACTOR` x the measurement-noise
    NMSE) or resolved (:data:`RESOLVED`: fit slack and restart errors keep complete models
    above the noise) and no channel on its own is unexplained (a clipped current is a
    few per cent of its channel and nothing on the others, below the mean's level); else
    *unexplained*. A named effect that leaves a
    residual above that level is *named; rest unexplained*: the gap shrank, but what remains
    is not noise and no further candidate explains it. The next experiments: the
    identification protocol of every untestable effect that is not in the model, and, for an
    unexplained residual, of the two best-ranked candidates.
    """
    resolved = at_noise_level(final, noise) and not channels_unexplained
    if steps:
        outcome = "named" if resolved else "named; rest unexplained"
    elif resolved:
        outcome = "nothing missing"
    else:
        outcome = "unexplained"
    names = [n for n in untestable_why if n not in given.effects]
    if outcome.endswith("unexplained"):
        names = [c["name"] for c in candidates[:2]] + names
    protocols = list(dict.fromkeys(REGISTRY[n].protocol for n in names if REGISTRY[n].protocol))
    return outcome, [f"hdgym experiment {p}" for p in protocols]
