"""The rules that pick the resonance task's deadline and gear rating from a measured front.

The task (``HarmonicDriveResonance-v0``) fails an episode whose |flexspline
torque| exceeds the rating and needs the target by the deadline. Both values
come from the front of the tuned classical families (:mod:`agents.front`,
training episodes only, so the held-out episodes and the policy play no part),
in this order:

1. **Deadline** (:func:`deadline_rule`): the shortest deadline of the front at
   which every base family reaches the target in >= 90 % of the training
   episodes with the torque uncapped. Any sensible controller is then on time
   when torque is free: the deadline alone is not the obstacle.
2. **Rating** (:func:`rating_rule`): at that deadline, the smallest torque cap
   of the front's grid at which the best base family succeeds in >= 50 % of the
   training episodes: the task sits where tuned classical control is half-way,
   neither trivial nor beyond reach. It must not exceed the drive's rated
   maximum (:data:`RATED_MAXIMUM`): Tuttle's thesis keeps no catalog numbers,
   but says joint 1's stiffness test reached 35 % of the drive's rated maximum
   torque and that test ended at 100 N m, so the rated maximum is about
   100 / 0.35 = 286 N m.
3. **Long deadline** (:func:`long_deadline_rule`), on the *long front*: the
   same families measured on the long variant's episodes
   (:data:`hdgym.envs.resonance.LONG_EPISODE`, 6 s), deadlines up to 5.5 s. At
   the rating, the shortest deadline from which the best base family's
   training success gains no more than one training episode up to the long
   front's longest deadline: past it, more time no longer helps tuned classical
   control. It must be longer than the deadline and shorter than the long
   front's longest deadline (else the front does not show where the gain
   stops, and the long episode must be longer).

"Base families" are the families tuned over the whole front; the KE
feedforward (``<family>+ke``) is tuned on top of the pick at the rating and
deadline, so it cannot take part in choosing them. :func:`check_constants`
compares the rules' values with the registered constants of
:mod:`hdgym.envs.resonance`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

#: fraction of training episodes every base family must reach the target in, uncapped
DEADLINE_REACH = 0.9
#: fraction of training episodes the best base family succeeds in at the rating
RATING_SUCCESS = 0.5
#: N m, Tuttle's joint-1 drive's rated maximum torque: 100 N m is 35 % of it
RATED_MAXIMUM = 100.0 / 0.35
#: the preset whose trap the task runs through
PRESET = "tuttle-joint1"


def base_families(front: Mapping[str, Any]) -> dict[str, Any]:
    """The families tuned over the whole front (not ``<family>+ke``)."""
    return {k: f for k, f in front["families"].items() if "+" not in k}


def deadline_rule(front: Mapping[str, Any]) -> tuple[float, dict[str, float]]:
    """The deadline (s) and every base family's uncapped training success at it.

    Uncapped is the front's largest cap. Raises ``ValueError`` when no
    deadline of the front qualifies."""
    j = len(front["caps"]) - 1
    fams = base_families(front)
    if not fams:
        raise ValueError("the front has no base families")
    for i, d in enumerate(front["deadlines"]):
        reach = {k: f["front"][i][j]["train"] for k, f in fams.items()}
        if min(reach.values()) >= DEADLINE_REACH:
            return float(d), reach
    raise ValueError(f"no deadline of the front ({front['deadlines']} s) has every base family "
                     f"reach the target in >= {DEADLINE_REACH:.0%} of the training episodes "
                     f"uncapped at {front['caps'][j]} N m")


def best_base_success(front: Mapping[str, Any], deadline: float) -> dict[float, float]:
    """Cap (N m) -> the best base family's training success at ``deadline`` (s)."""
    i = front["deadlines"].index(deadline)
    fams = base_families(front).values()
    return {float(cap): max(f["front"][i][j]["train"] for f in fams)
            for j, cap in enumerate(front["caps"])}


def rating_rule(front: Mapping[str, Any], deadline: float) -> tuple[float, dict[float, float]]:
    """The rating (N m) and the best base family's training success per cap at ``deadline``.

    Raises ``ValueError`` when no cap of the front reaches :data:`RATING_SUCCESS`
    or the cap found exceeds :data:`RATED_MAXIMUM`."""
    best = best_base_success(front, deadline)
    for cap, s in best.items():
        if s >= RATING_SUCCESS:
            if cap > RATED_MAXIMUM:
                raise ValueError(f"the rating rule gives {cap:g} N m, above the drive's rated "
                                 f"maximum of {RATED_MAXIMUM:.0f} N m")
            return cap, best
    raise ValueError(f"no cap of the front reaches {RATING_SUCCESS:.0%} success at the "
                     f"{deadline:g} s deadline")


def long_deadline_rule(long_front: Mapping[str, Any], rating: float, deadline: float
                       ) -> tuple[float, dict[float, float]]:
    """The long variant's deadline (s) and the best base family's training success at the
    rating per deadline of ``long_front`` (measured on the long variant's episodes).

    The shortest deadline whose best training success is within one training episode
    (``1 / n``, ``n`` the front's training episodes) of the best at the front's longest
    deadline. Raises ``ValueError`` when that deadline is not longer than ``deadline`` or
    is the front's longest (the front then shows no deadline where the gain stops)."""
    j = long_front["caps"].index(rating)
    fams = base_families(long_front).values()
    if not fams:
        raise ValueError("the long front has no base families")
    best = {float(d): max(f["front"][i][j]["train"] for f in fams)
            for i, d in enumerate(long_front["deadlines"])}
    n = long_front.get("train_seeds", [0, 64])[1]
    last = best[max(best)]
    d = min(x for x, s in best.items() if s >= last - 1.0 / n - 1e-12)
    if d <= deadline:
        raise ValueError(f"the long deadline {d:g} s is not longer than the deadline "
                         f"{deadline:g} s: more time does not help the classical families")
    if d >= max(best):
        raise ValueError(f"the best classical success at {rating:g} N m still grows at the "
                         f"long front's longest deadline {max(best):g} s; lengthen "
                         "LONG_EPISODE so the front shows where it stops")
    return d, best


def rules(front: Mapping[str, Any], long_front: Mapping[str, Any] | None = None
          ) -> dict[str, Any]:
    """The three rules: ``deadline``, ``rating`` on ``front`` (the default variant's
    episodes), ``long_deadline`` on ``long_front`` (the long variant's; without it
    ``long_deadline`` is None), and the numbers behind them
    (``uncapped_train_success`` per family at the deadline, ``best_train_success``
    per cap at the deadline, ``long_best_train_success`` per deadline of the long front
    at the rating)."""
    d, reach = deadline_rule(front)
    r, best = rating_rule(front, d)
    out: dict[str, Any] = {"deadline": d, "rating": r, "long_deadline": None,
                           "uncapped_train_success": reach, "best_train_success": best,
                           "long_best_train_success": {}}
    if long_front is not None:
        out["long_deadline"], out["long_best_train_success"] = long_deadline_rule(
            long_front, r, d)
    return out


def registered() -> dict[str, float]:
    """The registered constants of :mod:`hdgym.envs.resonance` (and ``long_episode``, s).

    Raises ``ValueError`` when the Long variant's registration (written apart in
    :mod:`hdgym.envs` so that registering stays light) disagrees with them."""
    from hdgym.envs import RESONANCE_STEPS, RESONANCE_VARIANTS
    from hdgym.envs.resonance import DEADLINE, GEAR_RATINGS, LONG_DEADLINE, LONG_EPISODE

    long_id = "HarmonicDriveResonanceLong-v0"
    if RESONANCE_VARIANTS[long_id].get("deadline") != LONG_DEADLINE:
        raise ValueError(f"{long_id} is registered with deadline "
                         f"{RESONANCE_VARIANTS[long_id].get('deadline')} s, LONG_DEADLINE is "
                         f"{LONG_DEADLINE} s")
    if RESONANCE_STEPS[long_id] != round(LONG_EPISODE * 1000):
        raise ValueError(f"{long_id} is registered with {RESONANCE_STEPS[long_id]} steps, "
                         f"LONG_EPISODE is {LONG_EPISODE} s of 1 ms periods")
    return {"deadline": DEADLINE, "rating": GEAR_RATINGS[PRESET], "long_deadline": LONG_DEADLINE,
            "long_episode": LONG_EPISODE}


CONSTANT_NAMES = {"deadline": "DEADLINE", "rating": f'GEAR_RATINGS["{PRESET}"]',
                  "long_deadline": "LONG_DEADLINE"}


def check_constants(ruled: Mapping[str, Any], have: Mapping[str, float] | None = None
                    ) -> list[str]:
    """The edits to hdgym/envs/resonance.py that make its constants follow the rules
    (``NAME = value`` lines; empty when they agree; a rule value of None, e.g. no long
    front given, is not checked). ``LONG_DEADLINE`` is also written in
    ``hdgym.envs.RESONANCE_VARIANTS``."""
    have = registered() if have is None else have
    return [f"{CONSTANT_NAMES[k]} = {float(ruled[k])!r}" for k in CONSTANT_NAMES
            if ruled.get(k) is not None and abs(float(ruled[k]) - float(have[k])) > 1e-9]
