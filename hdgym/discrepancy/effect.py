"""What the workflow knows of one effect: :class:`Effect`, its fit parameters and data scales."""

from __future__ import annotations

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
        current_measured: largest measured current, A (0 when not measured).
        voltage: largest voltage the amplifier was asked for, V.
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
    """

    torque: float
    speed: float
    torsion: float
    current: float
    current_measured: float = 0.0
    voltage: float = 0.0
    locked: bool = False
    inverse: bool = False
    transmission_error: float = 0.0
    ke: tuple[tuple[float, str, float, float], ...] = ()
    ripple: tuple[tuple[float, float, float], ...] = ()
    static: tuple[tuple[str, float, float], ...] = ()


@dataclass(frozen=True)
class FitParam:
    """One fitted parameter: dotted ``path``, bounds and an initial guess (None: keep)."""

    path: str
    lower: float
    upper: float
    guess: float | None = None


@dataclass(frozen=True)
class Effect:
    """One effect of the vocabulary, as the workflow sees it.

    Attributes:
        name: the vocabulary word.
        signature: key of its signature function in ``residuals.SIGNATURES``.
        description: one line for reports.
        requires: effects that must be on for this one to act.
        testable: ``testable(scales)`` -> whether the record can show it at all.
        sized: ``sized(scales)`` -> whether :meth:`switch_on` reads its size
            parameters (those with lower bound 0) from the record; the trial start
            then searches near them instead of over their whole range.
    """

    name: str
    signature: str
    description: str
    _params: Callable[[JointParams, Scales], list[FitParam]] = field(repr=False)
    _on: Callable[[JointParams, Scales], dict[str, Any]] = field(repr=False)
    _neutral: Callable[[dict[str, Any]], None] = field(repr=False)
    requires: tuple[str, ...] = ()
    testable: Callable[[Scales], bool] = field(default=lambda s: True, repr=False)
    sized: Callable[[Scales], bool] = field(default=lambda s: False, repr=False)

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

    def switch_on(self, p: JointParams, s: Scales) -> JointParams:
        """``p`` with this effect (and what it requires) on, at data-scaled initial guesses."""
        d = to_dict(p)
        for path, value in self._on(p, s).items():
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


def free_output(s: Scales) -> bool:
    """The output moves (not a locked-output record)."""
    return not s.locked


def simulated(s: Scales) -> bool:
    """The comparison re-simulates the record (not the inverse-dynamics one)."""
    return not s.inverse


def free_simulated(s: Scales) -> bool:
    """Free output and a simulated comparison."""
    return not s.locked and not s.inverse
