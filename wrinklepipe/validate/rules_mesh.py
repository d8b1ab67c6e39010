"""Rules on the mesh: tangents, vertex IDs, morph targets (WP-MESH-*)."""

from __future__ import annotations

import numpy as np

from wrinklepipe.asset import Mesh
from wrinklepipe.geometry.tangents import mikktspace_tangents
from wrinklepipe.validate.catalogue import Issue, make_issue
from wrinklepipe.validate.context import Context
from wrinklepipe.validate.rules_weights import group_spread


def reference_tangents(mesh: Mesh) -> tuple[np.ndarray, float, str]:
    """(tangents [V, 4], allowed angle in degrees, name): MikkTSpace from the geometry stage
    (it reproduces the Khronos sample's exported tangents to 0.03 degrees)."""

    t = mikktspace_tangents(mesh.positions, mesh.normals, mesh.uvs, mesh.indices)
    return np.asarray(t, np.float64), 5.0, "MikkTSpace"


def check_mesh(ctx: Context) -> list[Issue]:
    a, inp = ctx.asset, ctx.inp
    mesh = a.mesh
    where = inp.pointer("mesh")
    if mesh is None or mesh.uvs is None:
        what = "no mesh" if mesh is None else "a mesh without UVs"
        return [
            make_issue("WP-MESH-006", f"the asset has {what}; the render pass cannot run", where)
        ]
    out: list[Issue] = []
    v = mesh.vertex_count
    out += _tangent_issues(ctx, where)
    if mesh.vertex_ids is not None and len(mesh.vertex_ids) == v:
        ids = np.asarray(mesh.vertex_ids, np.int64)
        groups = ctx.vertex_groups
        spread = group_spread(groups, ids[:, None].astype(np.float64))
        bad = spread > 0
        if bad.any():
            first = int(np.flatnonzero(bad)[0])
            out.append(
                make_issue(
                    "WP-MESH-003",
                    f"{int(bad.sum())} vertices share a position with a twin of another ID "
                    f"(first vertex {first}, id {int(ids[first])})",
                    where + f" vertex {first}",
                )
            )
        _, id_groups = np.unique(ids, return_inverse=True)
        p = np.asarray(mesh.positions, np.float64)
        diag = float(np.linalg.norm(p.max(axis=0) - p.min(axis=0))) or 1.0
        pspread = group_spread(id_groups.reshape(-1), p)
        badp = pspread > 1e-5 * diag
        if badp.any():
            first = int(np.flatnonzero(badp)[0])
            out.append(
                make_issue(
                    "WP-MESH-004",
                    f"{int(badp.sum())} vertices share an ID with a vertex at another position "
                    f"(first vertex {first}, id {int(ids[first])}, {pspread[first]:.3g} apart)",
                    where + f" vertex {first}",
                )
            )
    names = tuple(mesh.morph_names)
    deltas = mesh.morph_deltas
    n_deltas = 0 if deltas is None else int(np.asarray(deltas).shape[0])
    if (names or n_deltas) and len(names) != n_deltas:
        out.append(
            make_issue(
                "WP-MESH-005",
                f"{len(names)} morph-target names but {n_deltas} morph targets",
                where,
            )
        )
    if deltas is not None and n_deltas and np.asarray(deltas).shape[1] != v:
        out.append(
            make_issue(
                "WP-MESH-005",
                f"morph targets have {np.asarray(deltas).shape[1]} vertices, the mesh {v}",
                where,
            )
        )
    for i, d in enumerate(a.drivers):
        if d.get("kind") != "blendshapes":
            continue
        wanted = d.get("inputs") or d.get("morphs") or []
        if isinstance(wanted, dict):
            wanted = list(wanted)
        missing = [m for m in wanted if isinstance(m, str) and m not in names]
        if missing:
            out.append(
                make_issue(
                    "WP-MESH-005",
                    f"blendshapes driver {i} reads morph targets the mesh lacks: "
                    + ", ".join(repr(m) for m in missing[:5])
                    + (" ..." if len(missing) > 5 else ""),
                    inp.pointer("drivers") + f"/{i}",
                )
            )
    return out


def _tangent_issues(ctx: Context, where: str) -> list[Issue]:
    """WP-MESH-001 (no tangents) and WP-MESH-002 (tangents not MikkTSpace-like: length,
    orthogonality, handedness, direction against the reference tangents); records how many
    vertices are off in ``ctx.metrics``."""
    mesh, o = ctx.asset.mesh, ctx.options
    v = mesh.vertex_count
    out: list[Issue] = []
    if mesh.tangents is None:
        out.append(make_issue("WP-MESH-001", f"mesh {mesh.name!r} has no tangents", where))
    elif mesh.normals is not None:
        tg = np.asarray(mesh.tangents, np.float64)
        if tg.shape != (v, 4):
            out.append(
                make_issue(
                    "WP-MESH-002", f"tangents have shape {tg.shape}, expected ({v}, 4)", where
                )
            )
        else:
            n = np.asarray(mesh.normals, np.float64)
            ref, tol_deg, ref_name = reference_tangents(mesh)
            length = np.linalg.norm(tg[:, :3], axis=1)
            t = tg[:, :3] / np.maximum(length, 1e-30)[:, None]
            not_unit = np.abs(length - 1.0) > 0.01
            not_orth = np.abs(np.einsum("ij,ij->i", t, n)) > 0.1
            bad_w = np.abs(np.abs(tg[:, 3]) - 1.0) > 1e-3
            # reference tangents exist where some triangle had a UV gradient
            has_ref = np.linalg.norm(ref[:, :3], axis=1) > 0.5
            cos = np.einsum("ij,ij->i", t, ref[:, :3])
            off_dir = has_ref & (cos < np.cos(np.radians(tol_deg)))
            flip = has_ref & (np.sign(tg[:, 3]) != np.sign(ref[:, 3])) & ~bad_w
            bad = not_unit | not_orth | bad_w | off_dir | flip
            ctx.metrics["tangent_mismatch_vertices"] = int(bad.sum())
            if bad.sum() > max(o.max_bad_fraction * v, 0.01 * v):
                first = int(np.flatnonzero(bad)[0])
                parts = [
                    f"{int(x.sum())} {label}"
                    for x, label in (
                        (not_unit, "not unit"),
                        (not_orth, "not orthogonal to the normal"),
                        (bad_w, "with |w| != 1"),
                        (off_dir, f"more than {tol_deg:g} degrees off {ref_name}"),
                        (flip, "with flipped handedness"),
                    )
                    if x.any()
                ]
                out.append(
                    make_issue(
                        "WP-MESH-002",
                        f"{int(bad.sum())} of {v} tangents are not MikkTSpace-like ("
                        + ", ".join(parts)
                        + f"); first vertex {first}",
                        where + f" vertex {first}",
                    )
                )
    return out
