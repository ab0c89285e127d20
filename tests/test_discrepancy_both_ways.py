"""A diagnosis that names nothing and leaves the residual unexplained searches again, with
every candidate trial-refitted and with its two records' roles swapped; one that finds
nothing missing checks that with the roles swapped (:func:`hdgym.discrepancy.workflow.diagnose`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from types import SimpleNamespace

import pytest


@dataclass
class _OneWay:
    """What :func:`.workflow.diagnose` reads of a one-way diagnosis."""

    source: str
    outcome: str
    steps: list = field(default_factory=list)
    validation: object = "checked"
    conclusion: str = ""
    seconds: float = 0.0
    next_experiments: list = field(default_factory=list)
    unexplained_channels: dict = field(default_factory=dict)


def _one_way_stub(monkeypatch, answers: list[_OneWay]) -> list[tuple]:
    """``workflow._one_way`` giving ``answers`` in turn; the calls as (searched, checked,
    the least linearized share for a trial refit)."""
    from hdgym.discrepancy import workflow as W

    calls, todo = [], list(answers)
    labels = LABELS
    labels.clear()

    def one_way(record, params, validate, min_score=W.MIN_SCORE, desc="diagnose", **kw):
        calls.append((record.source, getattr(validate, "source", None), min_score))
        labels.append(desc)
        return todo.pop(0)

    monkeypatch.setattr(W, "_one_way", one_way)
    return calls


A, B = SimpleNamespace(source="a.csv"), SimpleNamespace(source="b.csv")
LABELS: list[str] = []
"""The progress-bar labels of the stub's calls, in order (cleared by each stub)."""


def test_an_unexplained_search_runs_again_with_every_candidate_then_the_records_swapped(
        monkeypatch):
    """Nothing named and the residual unexplained: the same records again with every
    candidate trial-refitted, then the validation record searched and the training record
    checking; the first diagnosis that names an effect is returned, else the first one with
    what the others read."""
    from hdgym.discrepancy.search import MIN_SCORE
    from hdgym.discrepancy.workflow import diagnose

    named = _OneWay("b.csv", "named", steps=["load_dependent_friction"], conclusion="found it")
    calls = _one_way_stub(monkeypatch, [_OneWay("a.csv", "unexplained"),
                                        _OneWay("a.csv", "unexplained"), named])
    d = diagnose(A, None, B)
    assert calls == [("a.csv", "b.csv", MIN_SCORE), ("a.csv", "b.csv", 0.0),
                     ("b.csv", "a.csv", MIN_SCORE)]
    # each search's progress bar says which it is
    assert LABELS == ["diagnose", "diagnose again, every candidate trial-refitted",
                      "diagnose again, the records' roles swapped"]
    assert d.source == "b.csv" and d.steps == named.steps
    assert d.conclusion.endswith("found it") and "roles swapped" in d.conclusion
    same = _OneWay("a.csv", "named", steps=["stribeck_friction"], conclusion="found that")
    calls = _one_way_stub(monkeypatch, [_OneWay("a.csv", "unexplained"), same])
    d = diagnose(A, None, B)
    assert len(calls) == 2 and d.steps == same.steps and d.conclusion.endswith("found that")
    calls = _one_way_stub(monkeypatch, [_OneWay("a.csv", "unexplained", conclusion="first"),
                                        _OneWay("a.csv", "unexplained"),
                                        _OneWay("b.csv", "nothing missing")])
    d = diagnose(A, None, B)
    assert len(calls) == 3 and d.source == "a.csv" and d.outcome == "unexplained"
    assert d.conclusion.startswith("first;") and d.conclusion.endswith("reads nothing missing")


@pytest.mark.parametrize("first", [
    _OneWay("a.csv", "named", steps=["stiction"]),
    _OneWay("a.csv", "named; rest unexplained", steps=["stiction"]),
    _OneWay("a.csv", "unexplained", validation=None),  # a blind validation record, set aside
    _OneWay("a.csv", "nothing missing", validation=None),  # a blind validation record, set aside
])
def test_the_search_runs_again_only_when_nothing_was_named_and_the_validation_record_judges(
        monkeypatch, first):
    from hdgym.discrepancy.workflow import diagnose

    calls = _one_way_stub(monkeypatch, [first])
    assert diagnose(A, None, B) is first and len(calls) == 1
    calls = _one_way_stub(monkeypatch, [_OneWay("a.csv", "unexplained")])
    assert diagnose(A, None).outcome == "unexplained"
    assert len(calls) == 1  # no validation record: no check for a second search


def test_nothing_missing_must_hold_with_the_records_roles_swapped(monkeypatch):
    """*Nothing missing* is checked once with the validation record searched and the
    training record checking: nothing missing there too keeps it; an effect named there is
    returned; *unexplained* there makes the outcome *unexplained*, with both searches' next
    experiments."""
    from hdgym.discrepancy.search import MIN_SCORE
    from hdgym.discrepancy.workflow import diagnose

    calm = _OneWay("a.csv", "nothing missing", conclusion="first")
    calls = _one_way_stub(monkeypatch, [calm, _OneWay("b.csv", "nothing missing")])
    d = diagnose(A, None, B)
    assert calls == [("a.csv", "b.csv", MIN_SCORE), ("b.csv", "a.csv", MIN_SCORE)]
    assert LABELS[1] == "diagnose again, the records' roles swapped"
    assert d.outcome == "nothing missing" and d.source == "a.csv"
    assert d.conclusion.startswith("first;") and d.conclusion.endswith("reads nothing missing")
    named = _OneWay("b.csv", "named", steps=["stribeck_friction"], conclusion="found it")
    _one_way_stub(monkeypatch, [calm, named])
    d = diagnose(A, None, B)
    assert d.steps == named.steps and d.conclusion.endswith("found it")
    assert "nothing was missing" in d.conclusion
    calm.next_experiments = ["hdgym experiment breakaway_ramps"]
    left = _OneWay("b.csv", "unexplained", next_experiments=["hdgym experiment current_sine",
                                                             "hdgym experiment breakaway_ramps"])
    _one_way_stub(monkeypatch, [calm, left])
    d = diagnose(A, None, B)
    assert d.outcome == "unexplained" and d.source == "a.csv" and not d.steps
    assert d.next_experiments == ["hdgym experiment breakaway_ramps",
                                  "hdgym experiment current_sine"]
    assert "swapped" in d.unexplained_channels and d.conclusion.endswith("reads unexplained")
