"""Rig coverage (WP-WGT-004 .. WP-WGT-009): do the asset's drivers ever show its wrinkles?

The poses are those the drivers produce (:func:`wrinklepipe.validate.poses.render_poses`: the
expression table when it is played, each curve's per-region peak frames), so a region that no
pose activates is one no frame of any driver ever weights. What the drivers read (which clip of
which file, which blend shapes, whether they move) comes from the asset's provenance
(``provenance["drivers"]``: :func:`wrinklepipe.pipeline.drivers.evaluate_drivers`'s records,
kept by convert, ``validate-asset MANIFEST`` and the corpus bundles); without it, the rules
judge the curves alone.

- WP-WGT-004 (error): no pose activates any region: the rig is dead. One message naming each
  driver, why it gives nothing, and the regions; nothing below repeats it.
- WP-WGT-005 (warning): a region no pose activates (the rig is otherwise alive).
- WP-WGT-006 (warning): a state no pose reaches.
- WP-WGT-007 (warning): a driver read a clip the tool chose among several.
- WP-WGT-008 (info): an expression table and driver curves are both present: the curves drive
  the wrinkles (and the poses judged); said once.
- WP-WGT-009 (warning): a blend-shape driver whose inputs never move, in its clip or keys (and,
  for a file, in any clip of it), while another driver keeps the rig alive.

Per-vertex drivers (``bones``, ``dynamic``) weight vertices, not regions: with one, which
regions are driven is not in the asset's curves and coverage is not judged.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from wrinklepipe.drivers.clips import describe_clip
from wrinklepipe.drivers.poses import PER_VERTEX_KINDS, curve_kinds
from wrinklepipe.validate.catalogue import Issue, make_issue
from wrinklepipe.validate.context import Context
from wrinklepipe.validate.poses import render_poses


def _names(xs: list[str] | tuple[str, ...], limit: int = 8) -> str:
    shown = ", ".join(xs[:limit])
    return shown + (f" and {len(xs) - limit} more" if len(xs) > limit else "")


def why_idle(rec: dict[str, Any]) -> str:
    """Why a driver gives no weight, from its record (``''`` when the record cannot say)."""
    inputs = list(rec.get("inputs", []))
    if not inputs or rec.get("moving"):
        return ""
    clip = rec.get("clip")
    if clip:
        where = f"every frame of its {describe_clip(clip)}"
        if not clip.get("clips_moving") and len(clip.get("clips", [])) > 1:
            where += f" and in every other clip of {clip.get('file')}"
    else:
        where = f"every frame of its {rec.get('from', 'keys')}"
    what = "blend shapes" if rec.get("kind") == "blendshapes" else "curves"
    return f"its {what} {_names(inputs)} stay 0 in {where}"


def check_rig(ctx: Context) -> list[Issue]:
    a, inp = ctx.asset, ctx.inp
    if not a.regions or not a.state_names:
        return []
    if any(str(d.get("kind")) in PER_VERTEX_KINDS for d in a.drivers):
        return []  # per-vertex weights: the regions they drive are not in the curves
    if not a.drivers and not a.expressions:
        return []  # nothing in the asset drives it: an engine does
    kinds = curve_kinds(a.drivers)
    records = {str(r.get("name")): r for r in a.provenance.get("drivers", [])}
    where = inp.pointer("drivers")
    out: list[Issue] = []
    table_played = not a.drivers or "expressions" in kinds.values()
    if a.expressions and a.drivers and not table_played:
        out.append(
            make_issue(
                "WP-WGT-008",
                f"the expression table ({len(a.expressions)} expressions) and driver curves "
                f"({_names(sorted(kinds))}) are both present: the curves drive the wrinkles "
                "and the poses judged; the table ships for engines but is not played",
                inp.pointer("expressions"),
            )
        )
    regions = list(a.region_names)
    states = list(a.state_names)
    driven = np.zeros(len(regions), bool)
    reached = np.zeros(len(states), bool)
    for p in render_poses(inp):
        w = np.asarray(p.weights, np.float64)
        if a.policy == "signed":
            w = w.reshape(len(regions))
            driven |= w != 0
            if len(states) == 2:
                reached[0] |= bool((w < 0).any())
                reached[1] |= bool((w > 0).any())
            continue
        w = w.reshape(len(regions), -1)
        driven |= (w != 0).any(axis=1)
        on = (w != 0) if a.policy == "additive" else (w > 0)
        reached[: w.shape[1]] |= on.any(axis=0)
    if not driven.any():
        why = []
        for name, kind in kinds.items():
            reason = why_idle(records.get(name, {})) or "its curve is 0 in every frame"
            why.append(f"driver {name!r} ({kind}): {reason}")
        if table_played and a.expressions:
            why.append("the expression table weights no region")
        out.append(
            make_issue(
                "WP-WGT-004",
                "no pose of any driver activates a region, so no wrinkle ever shows: "
                + "; ".join(why)
                + f"; regions never driven: {_names(regions)}",
                where,
                regions=regions,
                clips=[r["clip"]["clip"] for r in records.values() if r.get("clip")],
            )
        )
        return out  # the one message: no per-region, per-state, per-driver or clip repeats
    for name, rec in sorted(records.items()):
        clip = rec.get("clip")
        if clip and clip.get("clips") and len(clip["clips"]) > 1 and not clip.get("named"):
            out.append(
                make_issue(
                    "WP-WGT-007",
                    f"driver {name!r} ({rec.get('kind')}) read {describe_clip(clip)}: the "
                    f'manifest names no clip; name one with clip = "..." in its [[drivers]] '
                    "table",
                    where + f"/{name}",
                    clip=clip.get("clip"),
                )
            )
    for r in np.flatnonzero(~driven):
        out.append(
            make_issue(
                "WP-WGT-005",
                f"region {regions[r]!r} is never driven: no pose of any driver "
                f"({_names(sorted(kinds)) or 'the expression table'}) gives it a weight",
                inp.pointer("masks"),
                region=regions[r],
            )
        )
    for k in np.flatnonzero(~reached):
        out.append(
            make_issue(
                "WP-WGT-006",
                f"state {states[k]!r} is never reached: no pose activates it (no driven region "
                "gives it a positive weight)",
                inp.pointer("meta"),
                state=states[k],
            )
        )
    for name, rec in sorted(records.items()):
        reason = why_idle(rec)
        if reason and rec.get("kind") == "blendshapes":
            out.append(
                make_issue(
                    "WP-WGT-009",
                    f"driver {name!r} (blendshapes) never moves: {reason}",
                    where + f"/{name}",
                )
            )
    return out
