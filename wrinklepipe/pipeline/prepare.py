"""Prepare: the asset brought to what the package needs.

Resampling to the manifest's resolutions (``"auto"``: the smallest within the error budget), the
mesh stage (normals, MikkTSpace tangents, spatial-hash vertex IDs) and the PD scale choice.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from wrinklepipe import masks as wm
from wrinklepipe import model
from wrinklepipe.asset import Mesh, WrinkleAsset
from wrinklepipe.errors import input_error
from wrinklepipe.geometry.normals import vertex_normals
from wrinklepipe.geometry.tangents import mikktspace_tangents
from wrinklepipe.geometry.vertex_ids import compute_vertex_ids
from wrinklepipe.io.package import resize_normals_pd
from wrinklepipe.normals.compress import Budget
from wrinklepipe.normals.encode import auto_pd_scale as _auto_pd_scale
from wrinklepipe.normals.resample import auto_size

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


def auto_wrinkle_size(asset: WrinkleAsset) -> tuple[int | None, dict[int, float]]:
    """Smallest power-of-two state size whose blended error over the expressions meets the
    budget (:func:`wrinklepipe.normals.resample.auto_size`); None when it cannot be chosen."""
    if asset.encoding != "pd" or not asset.expressions:
        return None, {}
    if asset.policy == "signed":
        return None, {}
    h = asset.states.shape[1]
    base = _resize_normals(asset.base, h)
    slopes = model.normal_to_pd(asset.states) - model.normal_to_pd(base)[None]
    masks = asset.masks
    if masks.shape[1] != h:
        masks = np.asarray(wm.resample_masks(masks, h), np.float32)
    weights = [asset.expression_weights({e: 1.0}) for e in sorted(asset.expressions)]
    b = asset.budget
    limits = Budget(b.get("max_mean_deg"), b.get("max_p99_deg", 2.0))
    size, tried = auto_size(base, slopes, masks, weights, limits, policy=asset.policy)
    return int(size), {int(k): float(v.p99_deg) for k, v in tried.items()}


# ------------------------------------------------------------------------------------------------
# the stages in order


@dataclass
class StageReport:
    """What the stages did, for report.json."""

    notes: list[str] = field(default_factory=list)
    pd_scale: float | None = None
    pd_scale_source: str = ""
    clipped_texels: dict[str, int] = field(default_factory=dict)


def run_stages(asset: WrinkleAsset, auto_scale: bool) -> tuple[WrinkleAsset, StageReport]:
    """Resample to the target resolutions, prepare the mesh, choose the PD scale."""
    rep = StageReport()
    res = dict(asset.resolution)
    base, states, masks = asset.base, asset.states, asset.masks
    if "wrinkle" in asset.provenance.get("auto_resolution", ()):
        size, tried = auto_wrinkle_size(asset)
        if size is not None:
            res["wrinkle"] = size
            rep.notes.append(
                "wrinkle resolution auto: "
                + ", ".join(f"{k}: p99 {v:.2f} deg" for k, v in sorted(tried.items()))
                + f" -> {size}"
            )
    if "base" in res and res["base"] != base.shape[0]:
        base = _resize_normals(base, int(res["base"]))
        rep.notes.append(f"base resampled to {res['base']}")
    if "wrinkle" in res and res["wrinkle"] != states.shape[1]:
        states = np.stack([_resize_normals(s, int(res["wrinkle"])) for s in states])
        rep.notes.append(f"wrinkle states resampled to {res['wrinkle']} (PD space)")
    if "mask" in res and res["mask"] != masks.shape[1]:
        masks = np.asarray(wm.resample_masks(masks, int(res["mask"])), np.float32)
        rep.notes.append(f"masks resampled to {res['mask']}")
    mesh = prepare_mesh(asset.mesh)
    rep.notes.extend(mesh.notes)
    asset = replace(asset, base=base, states=states, masks=masks, mesh=mesh)
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
        s = np.float32(asset.pd_scale)
        for k, name in enumerate(asset.state_names):
            rep.clipped_texels[name] = int(np.count_nonzero(np.any(np.abs(slopes[k]) > s, -1)))
    return asset, rep
