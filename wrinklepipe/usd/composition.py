"""USD composition errors, as plain records the validator turns into issues (WP-USD-xxx).

A stage with a missing or cyclic sublayer, reference or payload still opens: USD skips the arc
and reports it. :func:`composition_problems` reads what it reported (``GetCompositionErrors``,
and the diagnostics it posted while opening, captured by
:mod:`wrinklepipe.io.usd_diagnostics`) into :class:`UsdProblem` records that name the layer,
the asset path and the prim, one line each, deterministic (sorted, no memory addresses, no
session layers).
"""

from __future__ import annotations

import re
from dataclasses import asdict, dataclass
from typing import Any

#: Kinds of problem, in the order the validator's codes number them.
KINDS = (
    "missing_sublayer",
    "sublayer_cycle",
    "missing_arc",
    "arc_cycle",
    "composition",
    "diagnostic",
)

_MISSING_SUBLAYER = re.compile(r"Could not load sublayer @([^@]*)@ of layer @([^@]*)@")
_SUBLAYER_CYCLE = re.compile(
    r"Sublayer hierarchy with root layer @([^@]*)@ has cycles\. Detected when layer @([^@]*)@"
)
_MISSING_ARC = re.compile(
    r"Could not open asset @([^@]*)@ for (\w+) introduced by @([^@]*)@<([^>]*)>"
)
_UNRESOLVED_PRIM = re.compile(
    r"Unresolved (\w+) prim path @([^@]*)@<([^>]*)> introduced by @([^@]*)@<([^>]*)>"
)
_SITE = re.compile(r"(@[^@]*@(?:,@[^@]*@)*)(?:<([^>]*)>)?")


@dataclass(frozen=True, order=True)
class UsdProblem:
    """One composition problem: its kind (:data:`KINDS`), the layer that authored the arc, the
    asset path it names, the prim (may be empty) and one line saying it."""

    kind: str
    layer: str
    asset: str
    prim: str
    message: str

    def to_json(self) -> dict[str, str]:
        return asdict(self)


def _layer(text: str) -> str:
    """A layer identifier without the session layer an arc's site lists beside it."""
    return ",".join(p for p in text.split(",") if p and not p.startswith("anon:")) or text


def _one_line(text: str) -> str:
    line = " ".join(str(text).split())
    return re.sub(r"anon:0x[0-9a-fA-F]+:", "", line)


def _from_error(text: str, root: str) -> UsdProblem:
    """A Pcp error's text as a record."""
    if m := _MISSING_SUBLAYER.search(text):
        asset, layer = m.group(1), _layer(m.group(2))
        return UsdProblem(
            "missing_sublayer",
            layer,
            asset,
            "",
            f"sublayer @{asset}@ of {layer} cannot be opened (missing, or not a layer)",
        )
    if m := _SUBLAYER_CYCLE.search(text):
        asset, layer = m.group(1), _layer(m.group(2))
        return UsdProblem(
            "sublayer_cycle",
            layer,
            asset,
            "",
            f"sublayers form a cycle: {layer} is reached again through @{asset}@",
        )
    if m := _MISSING_ARC.search(text):
        asset, arc, layer, prim = m.group(1), m.group(2), _layer(m.group(3)), m.group(4)
        return UsdProblem(
            "missing_arc",
            layer,
            asset,
            prim,
            f"{arc} @{asset}@ on <{prim}> in {layer} cannot be opened (missing, or not a layer)",
        )
    if m := _UNRESOLVED_PRIM.search(text):
        arc, asset, target, layer, prim = m.groups()
        layer = _layer(layer)
        return UsdProblem(
            "missing_arc",
            layer,
            asset,
            prim,
            f"{arc} @{asset}@<{target}> on <{prim}> in {layer}: no such prim",
        )
    sites = [(_layer(a.strip("@").replace("@,@", ",")), p or "") for a, p in _SITE.findall(text)]
    if "Cycle detected" in text and sites:
        layer, prim = sites[0]
        chain = " -> ".join(f"{a}<{p}>" if p else a for a, p in sites)
        return UsdProblem(
            "arc_cycle", layer, sites[1][0] if len(sites) > 1 else "", prim,
            f"references or payloads form a cycle: {chain}",
        )  # fmt: skip
    layer, prim = sites[0] if sites else (root, "")
    return UsdProblem("composition", layer, "", prim, _one_line(text))


def composition_problems(stage: Any, diagnostics: list[str], root: str) -> list[UsdProblem]:
    """The stage's composition errors and, as ``diagnostic`` records, the other diagnostics USD
    posted while opening it (those repeating a composition error left out); ``root``: the root
    layer's path (named by records that have no layer of their own). Sorted, repeats removed."""
    out = {_from_error(str(e), root) for e in stage.GetCompositionErrors()}
    said = {_one_line(str(e)).split(". ")[0] for e in stage.GetCompositionErrors()}
    for line in diagnostics:
        text = _one_line(line)
        if any(s in text for s in said) or "Cycle detected" in text:
            continue
        out.add(UsdProblem("diagnostic", root, "", "", text))
    return sorted(out)
