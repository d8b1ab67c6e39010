"""A UDIM asset's validation: every tile on its own, then the whole face.

A tiled :class:`~wrinklepipe.validate.inputs.ValidationInput` holds one ordinary input per
tile (its textures, the mesh of its triangles with UVs in [0, 1]); every rule and the render
pass run on each (:func:`wrinklepipe.validate.run.validate`). One report is then made of them:

- every tile's issues, each message starting ``tile 1002:`` and its ``data`` naming the tile;
- the fidelity over the whole face: per pose, the texels of every tile pooled, weighted by
  activation and by the UV area a texel covers (:func:`wrinklepipe.fidelity.pooled`), judged
  by the same budget (WP-FID-001 ``over the whole face``), beside each tile's own
  (``metrics["fidelity_by_tile"]``: one row per tile and pose, and the face's);
- the render pass's and the pictures' per tile (pose names ``joy.1002``).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from wrinklepipe import fidelity as fd
from wrinklepipe.metrics import Budget
from wrinklepipe.validate.catalogue import Issue, make_issue

#: The row of ``metrics["fidelity_by_tile"]`` of the whole face.
FACE = "face"


#: Codes a tile raises for what may rightly be absent there: said only when every tile
#: raises it (a region's mask empty on one tile is a region painted on another).
EVERY_TILE_ONLY = ("WP-MASK-003",)


def tile_issue(issue: Issue, tile: int) -> Issue:
    """An issue of one tile's validation, said of that tile."""
    data = {**issue.data, "tile": tile}
    return replace(issue, message=f"tile {tile}: {issue.message}", data=data)


def merge_issues(per_tile: dict[int, list[Issue]]) -> list[Issue]:
    """Every tile's issues as the asset's: one said alike by every tile (the same code and
    message: a property of the description, or of every tile) once, ``every tile: ...``;
    the others each with its tile (:func:`tile_issue`), but those of
    :data:`EVERY_TILE_ONLY`, which only every tile together can say."""
    tiles = sorted(per_tile)
    seen: dict[tuple[str, str], list[int]] = {}
    for t in tiles:
        for i in per_tile[t]:
            seen.setdefault((i.code, i.message), []).append(t)
    out: list[Issue] = []
    done: set[tuple[str, str]] = set()
    for t in tiles:
        for i in per_tile[t]:
            key = (i.code, i.message)
            if len(set(seen[key])) == len(tiles) and len(tiles) > 1:
                if key not in done:
                    done.add(key)
                    data = {**i.data, "tile": "every"}
                    out.append(replace(i, message=f"every tile: {i.message}", data=data))
            elif i.code not in EVERY_TILE_ONLY:
                out.append(tile_issue(i, t))
    return out


def tile_images(images: dict[str, Any], tile: int, first: bool) -> dict[str, Any]:
    """A tile's pictures: ``kind/name`` -> ``kind/name.TILE``; the single pictures (the mask
    overlay, the region colours) are the first tile's."""
    out: dict[str, Any] = {}
    for k, v in images.items():
        if "/" in k:
            out[f"{k}.{tile}"] = v
        elif first:
            out[k] = v
    return out


def tile_render(render: dict[str, Any], tile: int) -> tuple[dict[str, Any], dict[str, Any]]:
    """A tile's render-pass record: its poses named ``pose.TILE``, and the rest."""
    poses = {f"{p}.{tile}": v for p, v in render.get("poses", {}).items()}
    rest = {k: v for k, v in render.items() if k != "poses"}
    return poses, rest


def face_fidelity(fids: dict[int, fd.Fidelity], areas: dict[int, float]) -> fd.Fidelity | None:
    """The whole face's fidelity from every tile's (:func:`wrinklepipe.fidelity.pooled`)."""
    parts = [(fids[t], areas[t]) for t in sorted(fids) if fids[t].samples]
    return fd.pooled(parts) if parts else None


def by_tile(fids: dict[int, fd.Fidelity], face: fd.Fidelity | None) -> dict[str, Any]:
    """``metrics["fidelity_by_tile"]``: ``"TILE pose"`` / ``"face pose"`` -> mean, p99, max,
    texels (the base over the face as pose ``base``)."""
    out: dict[str, Any] = {}
    rows = [*((str(t), fids[t]) for t in sorted(fids)), *([(FACE, face)] if face else [])]
    for name, fid in rows:
        for p in fid.poses:
            out[f"{name} {p.pose}"] = p.overall.to_json()
        if fid.base is not None:
            out[f"{name} base"] = fid.base.to_json()
    return out


def face_issues(face: fd.Fidelity, budget: Budget, which: str, where: str) -> list[Issue]:
    """WP-FID-001 / -003 of the whole face: its pooled poses and base over the budget."""
    out = []
    for p in sorted(face.over(budget), key=lambda p: -p.overall.p99):
        o = p.overall
        out.append(
            make_issue(
                "WP-FID-001",
                f"over the whole face (every tile): pose {p.pose!r}: p99 {o.p99:.2f}, mean "
                f"{o.mean:.2f}, max {o.max:.2f} degrees from the full-resolution source inside "
                f"its active region ({o.texels} texels), over the {which} ({budget.excess(o)})",
                where,
                pose=p.pose,
                p99_deg=round(o.p99, 4),
                mean_deg=round(o.mean, 4),
                tile="face",
            )
        )
    b = face.base
    if b is not None and not budget.ok(b):
        out.append(
            make_issue(
                "WP-FID-003",
                f"over the whole face (every tile): the shipped base differs from the source "
                f"base by p99 {b.p99:.2f}, mean {b.mean:.2f} degrees ({b.texels} texels), over "
                f"the {which} ({budget.excess(b)})",
                where,
                p99_deg=round(b.p99, 4),
                tile="face",
            )
        )
    return out
