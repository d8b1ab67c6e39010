"""Prepare: the asset brought to what the package needs.

Resampling to the manifest's resolutions, the mesh stage (normals, MikkTSpace tangents,
spatial-hash vertex IDs) and the PD scale; for ``pd`` the automatic choices (``"auto"`` sizes,
scale and block formats) by fidelity against the full-resolution source
(:mod:`wrinklepipe.pipeline.auto`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from wrinklepipe import fidelity as fd
from wrinklepipe import masks as wm
from wrinklepipe import model
from wrinklepipe.asset import Mesh, WrinkleAsset
from wrinklepipe.errors import input_error
from wrinklepipe.geometry.normals import vertex_normals
from wrinklepipe.geometry.tangents import mikktspace_tangents
from wrinklepipe.geometry.vertex_ids import compute_vertex_ids
from wrinklepipe.normals.encode import auto_pd_scale as _auto_pd_scale
from wrinklepipe.options import FormatOptions
from wrinklepipe.pipeline import auto
from wrinklepipe.pipeline.package import resize_normals_pd

# ------------------------------------------------------------------------------------------------
# mesh stage


def prepare_mesh(mesh: Mesh) -> Mesh:
    """Give the render mesh what the writers need: normals, tangents (always) and vertex IDs."""
    notes = list(mesh.notes)
    if mesh.uvs is None:
        raise input_error(mesh.name, "mesh has no UVs (wrinkle maps need a UV layout)")
    if mesh.normals is None:
        mesh = replace(mesh, normals=vertex_normals(mesh.positions, mesh.indices))
        notes.append("computed area-weighted vertex normals")
    if mesh.tangents is None:
        tangents = mikktspace_tangents(mesh.positions, mesh.normals, mesh.uvs, mesh.indices)
        notes.append("computed MikkTSpace tangents")
        mesh = replace(mesh, tangents=np.asarray(tangents, np.float32))
    if mesh.vertex_ids is None:
        ids = compute_vertex_ids(mesh.positions)
        notes.append("computed spatial-hash vertex IDs")
        mesh = replace(mesh, vertex_ids=np.asarray(ids, np.int64))
    return replace(mesh, notes=notes)


# ------------------------------------------------------------------------------------------------
# automatic choices


def _resize_normals(normals: np.ndarray, size: int) -> np.ndarray:
    return resize_normals_pd(normals, size, size)


def auto_pd_scale(slopes: np.ndarray, percentile: float = 99.9) -> float:
    """Smallest power of two >= the ``percentile`` of ``max(|dx|, |dy|)`` of the wrinkle slopes
    (:func:`wrinklepipe.normals.encode.auto_pd_scale`)."""
    return float(_auto_pd_scale(slopes, percentile))


# ------------------------------------------------------------------------------------------------
# the stages in order


@dataclass
class StageReport:
    """What the stages did, for report.json."""

    notes: list[str] = field(default_factory=list)
    #: the notes that matter to the verdict (why sizes were not searched), shown on the terminal
    key_notes: list[str] = field(default_factory=list)
    pd_scale: float | None = None
    pd_scale_source: str = ""
    fidelity: dict[str, Any] | None = None  # the automatic choices' record (auto.choice_report)
    formats: dict[str, str] = field(default_factory=dict)  # block formats for the copies


def run_stages(
    asset: WrinkleAsset,
    auto_scale: bool,
    formats: FormatOptions | None = None,
    compressed: bool = True,
    poses: Sequence[fd.Pose] | None = None,
) -> tuple[WrinkleAsset, StageReport]:
    """Resample to the target resolutions, prepare the mesh, choose the PD scale.

    For ``pd`` assets the automatic choices (sizes, scale, block formats) are made by fidelity
    against the full-resolution source (:mod:`wrinklepipe.pipeline.auto`); other encodings keep
    the manifest's sizes and the percentile scale. ``poses``: what the searches judge (convert
    passes the poses its drivers produce; default: the expression table).
    """
    rep = StageReport()
    res = dict(asset.resolution)
    base = asset.base
    if "base" in res and res["base"] != base.shape[0]:
        if asset.provenance.get("base_source") == "material":
            rep.notes.append(
                f"resolution.base {res['base']} ignored: the base is the wrinkled material's own "
                "normalTexture, which ships as it is"
            )
        else:
            base = _resize_normals(base, int(res["base"]))
            rep.notes.append(f"base resampled to {res['base']}")
            asset = replace(asset, base=base)
    mesh = prepare_mesh(asset.mesh)
    asset = replace(asset, mesh=mesh)
    why_not = auto.can_search(asset, poses)
    if not why_not:
        applied = auto.auto_choices(asset, formats, auto_scale, compressed, poses)
        asset = applied.asset
        rep.notes += applied.notes
        rep.fidelity = auto.choice_report(applied.choice)
        rep.formats = applied.formats
        rep.pd_scale = float(asset.pd_scale)
        rep.pd_scale_source = (
            "auto (least error inside the active regions, clipping included)"
            if auto_scale
            else "manifest"
        )
        rep.notes.extend(mesh.notes)
        return asset, rep
    if asset.provenance.get("auto_resolution"):
        rep.notes.append(f"automatic sizes not searched: {why_not}")
        rep.key_notes.append(rep.notes[-1])
    states, masks = asset.states, asset.masks
    if "wrinkle" in res and res["wrinkle"] != states.shape[1]:
        states = np.stack([_resize_normals(s, int(res["wrinkle"])) for s in states])
        rep.notes.append(f"wrinkle states resampled to {res['wrinkle']} (PD space)")
    if "mask" in res and res["mask"] != masks.shape[1]:
        masks = np.asarray(wm.resample_masks(masks, int(res["mask"])), np.float32)
        rep.notes.append(f"masks resampled to {res['mask']}")
    rep.notes.extend(mesh.notes)
    asset = replace(asset, states=states, masks=masks)
    if asset.encoding == "pd":
        b = base
        if b.shape[:2] != states.shape[1:3]:
            b = _resize_normals(base, states.shape[1])
        slopes = model.normal_to_pd(states) - model.normal_to_pd(b)[None]
        if auto_scale:
            asset = replace(asset, pd_scale=auto_pd_scale(slopes))
            rep.pd_scale_source = "auto (99.9th percentile of wrinkle slopes, power of two)"
        else:
            rep.pd_scale_source = "manifest"
        rep.pd_scale = float(asset.pd_scale)
    return asset, rep
