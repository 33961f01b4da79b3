"""One classification of the DSL's clauses (synth.parts CLAUSE_KINDS), checked against the grammar in docs/dsl.md;
the report's costs and the pictures' kinds are read from it."""

from __future__ import annotations

import re

from synth.dsl import parse_program
from synth.parts import CLAUSE_KINDS, all_parts
from tests.support import ROOT

DSL_MD = ROOT / "docs" / "dsl.md"
DEFAULTS = {"POS": "ahead of ego by Range(1, 2)", "HEADING": "facing toward ego", "MOTION": "stationary",
            "LANE": "off road"}
PARTS = tuple(DEFAULTS)


def documented_forms() -> list[tuple[str, str, int]]:
    """(part, clause text, cost) for every form the grammar lists, alternatives in parentheses spelled out."""
    grammar = DSL_MD.read_text().split("## Grammar", 1)[1].split("```")[1]
    forms, part = [], None
    for line in grammar.splitlines():
        m = re.match(r"\s*(?:(POS|HEADING|MOTION|LANE)\s*::=|\|)\s*(.*?)\s+cost (\d)\s*$", line)
        if not m:
            part = None
            continue
        part = m.group(1) or part
        text = m.group(2).replace("Range(a, b)", "Range(1, 2)").replace("Range(c, d)", "Range(3, 4)")
        text = text.replace("REF", "ego")
        choice = re.search(r"\(([^()]*\|[^()]*)\)", text)
        for alternative in (choice.group(1).split("|") if choice else [None]):
            spelled = text if alternative is None else text.replace(choice.group(0), alternative.strip())
            forms.append((part, spelled, int(m.group(3))))
    return forms


def test_every_documented_form_is_one_clause_kind_with_the_documented_cost():
    forms = documented_forms()
    assert len(forms) == 24  # 4 directions + 2, 2 facings + 2, 4 motions, 10 lane forms
    seen = []
    for part_name, text, cost in forms:
        clauses = {**DEFAULTS, part_name: text}
        statement = parse_program(f"car1 = new Car {', '.join(clauses[p] for p in PARTS)}\n")
        part, clause = list(statement.statements[0].clauses())[PARTS.index(part_name)]
        kinds = [k for k in part.clause_kinds if k.matches(clause)]
        assert len(kinds) == 1, text
        assert (kinds[0].cost, clause.kind) == (cost, kinds[0].label), text
        seen.append(kinds[0])
    assert sorted(seen, key=CLAUSE_KINDS.index) == list(CLAUSE_KINDS)  # each kind once, none undocumented
    assert len({k.label for k in CLAUSE_KINDS}) == len(CLAUSE_KINDS)
    assert [k for p in all_parts() for k in p.clause_kinds] == list(CLAUSE_KINDS)


def test_the_report_costs_and_the_pictures_kinds_are_the_classification():
    from pipeline.report.plots import KIND_COST
    from pipeline.variants.render import MARK_KINDS, RELATION_KINDS

    assert KIND_COST == {k.label: k.clause.cost for k in CLAUSE_KINDS}
    # A clause without a reference is marked on its entity, one with a reference is an arrow from it.
    for kind in CLAUSE_KINDS:
        assert kind.drawn_as in (RELATION_KINDS if "ref" in kind.clause.__dataclass_fields__ else MARK_KINDS)
