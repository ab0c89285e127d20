"""A diagnosis that names nothing and leaves the residual unexplained searches again with its
two records' roles swapped (:func:`hdgym.discrepancy.workflow.diagnose`)."""

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


def _one_way_stub(monkeypatch, outcomes: dict[str, _OneWay]) -> list[str]:
    """``workflow._one_way`` answering by the searched record's source; the sources searched."""
    from hdgym.discrepancy import workflow as W

    calls = []

    def one_way(record, params, validate, **kw):
        calls.append(record.source)
        return outcomes[record.source]

    monkeypatch.setattr(W, "_one_way", one_way)
    return calls


def test_an_unexplained_search_runs_again_with_the_records_swapped(monkeypatch):
    """Nothing named and the residual unexplained: the validation record is searched and
    the training record checks; the swapped diagnosis is returned when it names an effect,
    else the first one with what the other way read."""
    from hdgym.discrepancy.workflow import diagnose

    a, b = SimpleNamespace(source="a.csv"), SimpleNamespace(source="b.csv")
    named = _OneWay("b.csv", "named", steps=["load_dependent_friction"], conclusion="found it")
    calls = _one_way_stub(monkeypatch, {"a.csv": _OneWay("a.csv", "unexplained"),
                                        "b.csv": named})
    d = diagnose(a, None, b)
    assert calls == ["a.csv", "b.csv"] and d.source == "b.csv" and d.steps == named.steps
    assert d.conclusion.endswith("found it") and "roles swapped" in d.conclusion
    calls = _one_way_stub(monkeypatch, {"a.csv": _OneWay("a.csv", "unexplained"),
                                        "b.csv": _OneWay("b.csv", "nothing missing")})
    d = diagnose(a, None, b)
    assert calls == ["a.csv", "b.csv"] and d.source == "a.csv" and d.outcome == "unexplained"
    assert d.conclusion.endswith("it reads nothing missing")


@pytest.mark.parametrize("first", [
    _OneWay("a.csv", "named", steps=["stiction"]),
    _OneWay("a.csv", "named; rest unexplained", steps=["stiction"]),
    _OneWay("a.csv", "nothing missing"),
    _OneWay("a.csv", "unexplained", validation=None),  # a blind validation record, set aside
])
def test_the_records_swap_only_when_nothing_was_named_and_the_residual_is_unexplained(
        monkeypatch, first):
    from hdgym.discrepancy.workflow import diagnose

    calls = _one_way_stub(monkeypatch, {"a.csv": first})
    assert diagnose(SimpleNamespace(source="a.csv"), None, SimpleNamespace(source="b.csv")) \
        is first
    assert calls == ["a.csv"]
    calls = _one_way_stub(monkeypatch, {"a.csv": _OneWay("a.csv", "unexplained")})
    assert diagnose(SimpleNamespace(source="a.csv"), None).outcome == "unexplained"
    assert calls == ["a.csv"]  # no validation record: nothing to swap with
