"""The diagnosis's rules (boucwen.diagnosis.rules): one registry, every decision names one
of its rules, and docs/diagnosis.md lists exactly the registry."""

from pathlib import Path

import pytest

from boucwen.diagnosis.judge import Decision, Gain
from boucwen.diagnosis.rules import RULES, markdown, rule

DOCS = Path(__file__).resolve().parents[1] / "docs" / "diagnosis.md"


def test_the_docs_list_is_the_registry():
    text = DOCS.read_text(encoding="utf-8")
    block = text.split("<!-- rules -->\n", 1)[1].split("\n<!-- /rules -->", 1)[0]
    assert block == markdown()


def test_every_rule_has_a_stage_a_statement_and_a_reason():
    stages = {"folds", "screen", "candidate", "judge", "search", "report"}
    for name, r in RULES.items():
        assert r.name == name and r.stage in stages
        assert r.decides.endswith(".") and r.reason.endswith(".") and r.where


def test_a_decision_names_a_rule_of_the_registry():
    g = Gain(1.0, 0.1, 10.0, 1, 10, 100, (1.0,), 2.0)
    assert Decision("add", ("creep",), ("creep",), (), g, 2.0, 0.1, True, "x", 1).rule == "forward_gain"
    with pytest.raises(KeyError, match="no rule 'made_up'"):
        Decision("add", ("creep",), ("creep",), (), g, 2.0, 0.1, True, "x", 1, True, "made_up")
    with pytest.raises(KeyError, match="no rule"):
        rule("made_up")
