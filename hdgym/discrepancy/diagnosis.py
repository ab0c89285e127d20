"""The outcome of a diagnosis (:class:`Diagnosis`), below both the workflow that makes it
(:mod:`.workflow`) and the report that renders it (:mod:`.report`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from hdgym.params import JointParams

from .fitting import FitResult
from .friction_events import summary
from .problem import Problem

#: validation-NMSE cut (fraction) with which a generated case counts as passed / hit, when
#: the hidden effects are named first (:mod:`.cases`, :mod:`.holdout`)
HIT_CUT = 0.8


@dataclass
class Step:
    """One effect added: why, what was fitted, and the NMSE after it."""

    name: str
    evidence: dict
    values: dict[str, float]
    nmse: dict[str, float]
    nmse_validation: dict[str, float] | None
    relative_improvement: float
    candidates: list[dict]
    params: JointParams = field(repr=False)


@dataclass
class Diagnosis:
    """Everything :func:`diagnose` found (turned into report.json / report.md by :mod:`.report`)."""

    source: str
    mode: str
    channels: tuple[str, ...]
    base_effects: tuple[str, ...]
    nmse_given: dict[str, float]
    before: FitResult
    steps: list[Step]
    after: FitResult
    where_before: dict
    where_after: dict
    final_candidates: list[dict]
    conclusion: str
    nmse_given_validation: dict[str, float] | None = None
    nmse_before_validation: dict[str, float] | None = None
    nmse_after_validation: dict[str, float] | None = None
    validation_source: str | None = None
    untestable: list[str] = field(default_factory=list)
    seconds: float = 0.0
    problem: Problem | None = field(default=None, repr=False)
    validation: Problem | None = field(default=None, repr=False)
    fit_window: float | None = None
    nmse_record_before: dict[str, float] | None = None
    nmse_record_after: dict[str, float] | None = None
    outcome: str = ""
    horizon: float | None = None
    """Prediction horizon, s (multiple-shooting segment; None: inverse comparison)."""
    """``nothing missing``, ``named`` or ``unexplained`` (see :mod:`.workflow`)."""
    noise: dict[str, float] | None = None
    """Measurement-noise NMSE per channel of the record the outcome is judged on."""
    floor: float | None = None
    """The final model's comparison floor on that record, mean NMSE percent
    (:func:`.floor.floor_nmse`; what the outcome "named" is judged against)."""
    untestable_why: dict[str, str] = field(default_factory=dict)
    """Effect -> what the record would have to show for it to be seen."""
    next_experiments: list[str] = field(default_factory=list)
    compare: str = "time"
    """What before and after are NMSE of: ``time`` (the channels) or ``spring`` (the spring
    curve of a locked output, where the effect was found; :mod:`.spring`)."""
    unexplained_channels: dict[str, str] = field(default_factory=dict)
    """Channels whose own residual is neither noise nor fit slack (channel -> why;
    :func:`.floor.unexplained_channels`)."""
    """``hdgym experiment ...`` commands whose records would decide what this one cannot."""

    @property
    def friction_features(self) -> dict | None:
        """Friction features of the judged record (the validation record when there is one),
        the base fit and the final model, and their mismatch
        (:func:`.friction_events.summary`; None on locked or inverse records)."""
        judged = self.validation or self.problem
        if judged is None:
            return None
        return summary(judged, self.before.params, self.after.params)

    @property
    def missing_effects(self) -> list[str]:
        return [s.name for s in self.steps]

    @property
    def nmse_before(self) -> float:
        v = self.nmse_before_validation if self.nmse_before_validation else self.before.nmse
        return v["mean"]

    @property
    def nmse_after(self) -> float:
        v = self.nmse_after_validation if self.nmse_after_validation else self.after.nmse
        return v["mean"]

    @property
    def nmse_cut(self) -> float:
        """Fraction by which the added effects cut the mean NMSE (0 when there was none)."""
        b, a = self.nmse_before, self.nmse_after
        return 1.0 - a / b if b > 0 else 0.0
