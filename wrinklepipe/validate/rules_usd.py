"""Rules on a USD stage's composition (WP-USD-*): the missing or cyclic sublayers, references
and payloads, and the other diagnostics, USD reported opening the stage (the records
:mod:`wrinklepipe.usd.composition` makes, in ``extra["usd_composition"]`` of the input)."""

from __future__ import annotations

from wrinklepipe.validate.catalogue import Issue, make_issue
from wrinklepipe.validate.context import Context

#: Each kind of record and its code.
CODES = {
    "missing_sublayer": "WP-USD-001",
    "sublayer_cycle": "WP-USD-002",
    "missing_arc": "WP-USD-003",
    "arc_cycle": "WP-USD-004",
    "composition": "WP-USD-005",
    "diagnostic": "WP-USD-006",
}


def check_composition(ctx: Context) -> list[Issue]:
    out: list[Issue] = []
    for p in ctx.inp.extra.get("usd_composition", []):
        layer, prim = str(p.get("layer", "")), str(p.get("prim", ""))
        pointer = f"{layer}<{prim}>" if prim else layer
        code = CODES.get(str(p.get("kind")), "WP-USD-005")
        out.append(make_issue(code, str(p.get("message", "")), pointer or ctx.inp.path))
    return out
