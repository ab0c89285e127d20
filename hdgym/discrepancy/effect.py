"""What the workflow knows of one effect: :class:`Effect`, its fit parameters and data scales."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from hdgym.params import JointParams, from_dict, to_dict

from .paths import assign, fix_sides, get_value, set_in_dict


@dataclass(frozen=True)
class Scales:
    """Data-derived sizes used for bounds and initial guesses (all output-referred).

    Attributes:
        torque: typical transmitted torque, N m (motor torque constant x ratio
            x command range).
        speed: typical output speed, rad/s.
        torsion: typical torsion, output rad.
        current: largest commanded current, A.
        current_measured: the measured current's clip level, A (the largest measured
            current when nothing clipped; 0 when not measured; see
            :func:`.record_scales.clip_level`).
        voltage: the voltage's clip level where the measured current shows one, else the
            largest voltage the amplifier gave (or, current not measured, was asked for), V.
        voltage_unreached: the measured current shows the voltage limit never held it.
        locked: locked-output record.
        inverse: torque-domain (inverse-dynamics) comparison; the compliance,
            hysteresis, kinematic-error and amplifier effects are not testable.
        transmission_error: typical size of output - motor/ratio, output rad.
        ke: ``(order, port, a, b)`` guesses of kinematic-error lines
            ``a sin + b cos`` (output rad; ``order`` relative to ``port``, as in
            :class:`hdgym.params.Harmonic`), regressed from the measured
            transmission error at the lines :func:`ke_lines` says the record resolves.
        ripple: ``(order, a, b)`` guesses of output-side friction ripple (N m),
            regressed from the measured acceleration while moving.
        static: ``(side, static, running)`` friction levels read from the record's
            pauses and runs (:func:`.residuals.friction_levels`; side ``output``,
            ``input`` or ``lumped``, N m in the side's frame): the largest torque
            held while stuck and the sign-of-velocity level while moving.
        moving: share of the samples in which the motor (WG) moves faster than 10 %
            of its 90th-percentile speed.
        reversals: how often the motor speed changes sign while moving.
        standstills: pauses in which the measured joint stands still (no encoder
            count for :data:`.restarts.REST_PAUSE`), each a breakaway to come.
        wg_turns: WG revolutions the record spans.
        speed_spread: 90th over 10th percentile of the moving speed.
        band_time: seconds the record moves below 1/1.5 of its 90th-percentile moving
            speed (a run-up from rest passes there on its way to speed).
        torsion_measured: the record shows the torsion (locked output, a torque sensor,
            or a transmission error above the output encoder's resolution).
        te_measured: the transmission error is a compared channel.
        torque_share: largest transmitted torque over the drive's peak torque (torque
            constant x ratio x the model's current limit, or the largest command).
        moving_torque_share: the same, 90th percentile over the moving samples.
        spring: the comparison is the spring curve of a locked output (:mod:`.spring`:
            residuals averaged over bins of the measured torque), where the noise averages
            out and a bend shows at any torque.

    The defaults of the record facts (``moving`` on) say "the record shows everything".
    """

    torque: float
    speed: float
    torsion: float
    current: float
    current_measured: float = 0.0
    voltage: float = 0.0
    voltage_unreached: bool = False
    locked: bool = False
    inverse: bool = False
    transmission_error: float = 0.0
    ke: tuple[tuple[float, str, float, float], ...] = ()
    ripple: tuple[tuple[float, float, float], ...] = ()
    static: tuple[tuple[str, float, float], ...] = ()
    moving: float = 1.0
    reversals: int = 2
    standstills: int = 1
    wg_turns: float = math.inf
    speed_spread: float = math.inf
    band_time: float = math.inf
    torsion_measured: bool = True
    te_measured: bool = True
    torque_share: float = 1.0
    moving_torque_share: float = 1.0
    spring: bool = False


@dataclass(frozen=True)
class Condition:
    """What a record must show for an effect to be seen: ``needs`` (words) and the check.

    ``size``: the condition asks only how far into the effect's range the record goes (a
    share of the drive's peak torque), not for a kind of motion that sets the effect apart
    from others; a record that misses it still moves with the effect's parameters.
    """

    needs: str
    check: Callable[[Scales], bool] = field(repr=False)
    size: bool = False


FREE = Condition("a free output (this record's output is locked)", lambda s: not s.locked)
SIMULATED = Condition("a current command to re-simulate (this is a closed-loop record, compared "
                      "in the torque domain)", lambda s: not s.inverse)
MOVING = Condition("motion (the joint moves in at least 20 % of the record)",
                   lambda s: s.moving >= 0.2)
TURNS = Condition("at least two WG revolutions of motion", lambda s: s.wg_turns >= 2.0)
REVISIT_TURNS = 0.05
"""Least WG revolutions a record that crosses its angle range back and forth must span for a
kinematic error to show: over a twentieth of a turn the dominant order-2 line sweeps 72 deg of
its phase, so it varies by at least a fifth of its amplitude (1 - cos 36 deg) wherever on the
circle the range lies; the base model cannot make a transmission error that repeats with the
WG angle. Was a quarter turn (half the line's period); measured on the development seeds
(14-170), a twentieth reaches 11 free-output sine records that cross 0.056-0.23 turns back and
forth (23 reversals). The two with a hidden kinematic error, untestable before, now name it
first (tuttle-joint3 / kinematic_error / sine:0.178:2, seed 170: validation NMSE 187 -> 9.9 %
on the horizon reported, 96 % of the gap); on the four run with another effect or none hidden
(stiction, position-dependent friction, none twice) nothing is named falsely."""
TURNS_OR_REVISITS = Condition(
    "at least two WG revolutions of motion, or a twentieth of a revolution crossed back and "
    "forth (two reversals or more: the transmission error repeats at the same WG angles)",
    lambda s: s.wg_turns >= 2.0 or (s.wg_turns >= REVISIT_TURNS and s.reversals >= 2))
TE = Condition("a transmission error above the output encoder's resolution",
               lambda s: s.te_measured)
TORSION = Condition("the torsion (a locked output, a torque sensor or the transmission error)",
                    lambda s: s.torsion_measured)
HIGH_TORQUE = Condition("torque beyond half the drive's peak torque (a hardening spring shows "
                        "at high torsion) or, on a locked output, the spring curve compared",
                        lambda s: s.torque_share >= 0.5 or s.spring, size=True)
REVERSALS = Condition("reversals (the motion changes direction at least twice)",
                      lambda s: s.reversals >= 2)
STANDSTILL = Condition("standstill and breakaway (the joint stops for 30 ms or more and starts "
                       "again)", lambda s: s.standstills >= 1)
LOW_SPEED = Condition("motion through low speed (a reversal or a start from rest)",
                      lambda s: s.reversals + s.standstills >= 1)
BAND_SPREAD = 1.5
"""Least ratio of two speeds a record must move at for friction that grows with speed to
show apart from the speed-independent level (:data:`SPEED_BAND`)."""
BAND_TIME = 0.05
"""Least seconds of motion below 1/:data:`BAND_SPREAD` of the typical moving speed that
make a band of speeds on their own (:data:`SPEED_BAND`): a run-up from rest to a top
speed crosses the band in about a time constant J/b, while the top speed fills most of
the record (the development case seyfferth-rh25 / viscous_friction / step:1.79, seed
122: 90th over 10th percentile 1.0, 0.25 s below two thirds of the top speed, and the
base model without viscous friction left 37 % NMSE against the true joint's 0.27 %).
The small drives run up faster: hduc20 and hdf40 steps spend 66-110 ms there (fifty
samples and more at 1 kHz), and with 0.1 s their viscous friction was untestable though
it changed the record by 30 % NMSE (development seed 194, hduc20 / viscous_friction /
step:3.24); with 0.05 s the seven such development cases of seeds 26-194 are named,
89-100 % of the gap."""
SPEED_SPREAD = Condition(
    f"speeds spread over the record (90th over 10th percentile of the moving speed >= "
    f"{BAND_SPREAD:g})", lambda s: s.speed_spread >= BAND_SPREAD)
"""Where a base model's own viscous friction is refitted (:attr:`Effect.refit`): a run-up
alone (:data:`SPEED_BAND`) shows that friction grows with speed, so the effect can be
tried and added, but its time constant J/b and top speed (tau - F_c)/b leave inertia,
viscous and Coulomb friction to trade against each other, so a given viscous coefficient
is refined there only late, within :data:`.registry.TOLERANCE` of its value (refitted
freely, it also cost the bench's 60 s tuttle-joint3 step record 23 % more simulations,
5,081 -> 6,272)."""
SPEED_BAND = Condition(
    f"a band of speeds (90th over 10th percentile of the moving speed >= {BAND_SPREAD:g}, or "
    f"{BAND_TIME:g} s or more of motion below 1/{BAND_SPREAD:g} of the 90th percentile: a "
    "run-up)",
    lambda s: SPEED_SPREAD.check(s) or s.band_time >= BAND_TIME)
LOADED = Condition("transmitted torque while moving beyond a fifth of the drive's peak torque",
                   lambda s: s.moving_torque_share >= 0.2, size=True)


@dataclass(frozen=True)
class FitParam:
    """One fitted parameter: dotted ``path``, bounds and an initial guess (None: keep).

    ``late``: refined only once the others have converged (:func:`.settle.converge`'s rounds
    after the first; a plain :func:`.fitting.fit` leaves it as it is): a given model's
    parameter of an effect the record reaches too little of to name
    (:func:`.registry.model_params`).
    """

    path: str
    lower: float
    upper: float
    guess: float | None = None
    late: bool = False


@dataclass(frozen=True)
class Effect:
    """One effect of the vocabulary, as the workflow sees it.

    Attributes:
        name: the vocabulary word.
        signature: key of its signature function in ``residuals.SIGNATURES``.
        description: one line for reports.
        requires: effects that must be on for this one to act.
        seen: the conditions under which a record reveals it (:class:`Condition`); the
            workflow compares the effect only on records that meet them all and lists
            it as untestable otherwise (:meth:`why_not`).
        channels: the comparison channels that show it.
        protocol: the identification protocol (``hdgym experiment NAME``) whose record
            reveals it: the next experiment when this record cannot.
        refit: further conditions under which the parameters of this effect, when the
            given base model already has it, are refitted (otherwise they are refined late
            within :data:`.registry.TOLERANCE` of their given values only): where the
            record shows the effect but cannot tell its parameters from those of other
            effects, it may be added (an addition must pass the checks of
            :func:`.workflow.diagnose`) but a base model's values move little.
        compare: the comparisons that reveal it: ``"time"`` (the channels sample by
            sample) and, for the spring's effects, ``"spring"`` (on a locked output, the
            residuals averaged over bins of the measured torque and its direction: the
            spring curve, :mod:`.spring`) and, for the order-line effects, ``"lines"``
            (on a free output, line amplitudes at orders of each run's own WG angle,
            :mod:`.orders`).
        sized: ``sized(scales)`` -> whether :meth:`switch_on` reads its size
            parameters (those with lower bound 0) from the record; the trial start
            then searches near them instead of over their whole range.
        forms: further named ways to switch it on, each a switch-on function like the
            default one (a hardening spring as a cubic or with a knee): the ranking finds a
            start in every form (:func:`.ranking._form_starts`) and the trial refit fits
            from each.
    """

    name: str
    signature: str
    description: str
    _params: Callable[[JointParams, Scales], list[FitParam]] = field(repr=False)
    _on: Callable[[JointParams, Scales], dict[str, Any]] = field(repr=False)
    _neutral: Callable[[dict[str, Any]], None] = field(repr=False)
    requires: tuple[str, ...] = ()
    seen: tuple[Condition, ...] = ()
    channels: str = ""
    protocol: str = ""
    compare: tuple[str, ...] = ("time",)
    sized: Callable[[Scales], bool] = field(default=lambda s: False, repr=False)
    refit: tuple[Condition, ...] = ()
    forms: tuple[tuple[str, Callable[[JointParams, Scales], dict[str, Any]]], ...] = field(
        default=(), repr=False)

    def why_not(self, s: Scales) -> str | None:
        """Why a record with scales ``s`` cannot reveal this effect (None: it can)."""
        missing = self._missing(s)
        return "needs " + "; ".join(c.needs for c in missing) if missing else None

    def _missing(self, s: Scales) -> list[Condition]:
        """The conditions of :attr:`seen` a record with scales ``s`` does not meet."""
        return [c for c in self.seen if not c.check(s)]

    def testable(self, s: Scales) -> bool:
        """Whether a record with scales ``s`` can reveal this effect."""
        return self.why_not(s) is None

    def too_small(self, s: Scales) -> bool:
        """Whether a record with scales ``s`` moves with this effect's parameters but does
        not reach far enough into its range to name it: not testable, and every condition
        it misses is a :attr:`Condition.size` one (a segmented spring below half the peak
        torque, tooth friction at light load). A base model that has the effect is off by
        its parameters there as much as by any other's."""
        missing = self._missing(s)
        return bool(missing) and all(c.size for c in missing)

    def fit_params(self, p: JointParams, s: Scales) -> list[FitParam]:
        """Parameters to fit for this effect, with bounds (containing the current value)."""
        out = []
        for fp in self._params(p, s):
            try:
                v = get_value(p, fp.path)
            except ValueError:
                v = fp.guess if fp.guess is not None else fp.lower
            lo, hi = min(fp.lower, v), max(fp.upper, v)
            out.append(FitParam(fp.path, lo, hi, fp.guess))
        return out

    def form_names(self) -> tuple[str | None, ...]:
        """The forms :meth:`switch_on` takes: None (the default) and each of ``forms``."""
        return (None, *(name for name, _ in self.forms))

    def switch_on(self, p: JointParams, s: Scales, form: str | None = None) -> JointParams:
        """``p`` with this effect (and what it requires) on, at data-scaled initial guesses
        (``form``: one of :attr:`forms` by name instead of the default)."""
        on = self._on if form is None else dict(self.forms).get(form)
        if on is None:
            raise ValueError(f"effect {self.name!r} has no form {form!r}")
        d = to_dict(p)
        for path, value in on(p, s).items():
            if path.startswith("@"):  # structural replacement of a whole table or list
                assign(d, path[1:], value)
            else:
                set_in_dict(d, path, value)
        fix_sides(d)
        q = from_dict(d, "params")
        return q.with_effects(self.name, *self.requires)

    def neutral(self, p: JointParams) -> JointParams:
        """``p`` with this effect's parameters set so that it does nothing (switch unchanged)."""
        d = to_dict(p)
        self._neutral(d)
        fix_sides(d)
        return from_dict(d, "params")
