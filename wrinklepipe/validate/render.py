"""The render pass: draw the mesh with the GLSL wrinkle model, compare with the numpy model.

The poses are those the drivers produce (:func:`wrinklepipe.drivers.poses.driver_poses`):
neutral, the expression table for ``expressions`` drivers (or none), and for other drivers'
curves the frames where each region's weight peaks, named by time (``blendshapes@1.000s``).
The mesh keeps its rest shape in every pose (every pixel compares the same surface point across
poses and with the numpy reference; a curve frame's morph weights are listed in the info). The
view is the front orthographic view fitted to the
mesh, which for a whole document is its wrinkled primitives only (other parts are left out).
For each pose the generated shaders (:mod:`wrinklepipe.shading`) render, in
one draw, a shaded image, the tangent-space normal buffer (float32) and the UV buffer. The numpy
reference (:func:`wrinklepipe.model.blend`) is evaluated at the rasterised UVs on the same
shipped texels (bilinear, clamp to edge, no mipmaps, like the GPU), so the two must agree to
within the GPU's filtering precision; a wrong colour-space tag or an unsupported format shows as
a disagreement. Wrinkles must change the render only where the source masks x weights are non-zero.

With colour states the shaders also blend colour (:mod:`wrinklepipe.shading.glsl`): the base
colour and the colour maps are uploaded as sRGB textures (the GPU decodes each texel before it
filters), the shaded image is lit with the blended albedo, and two more targets hold the albedo
and the object-space normal. The numpy colour model (:func:`wrinklepipe.model.combine_color`)
of the same shipped texels (decoded, then sampled bilinearly) gives the albedo, and lit with the
same light on the GPU's normal (:func:`shade_albedo`) the lit colour; both are compared in
CIEDE2000 (WP-RND-005).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage

from wrinklepipe import model
from wrinklepipe.codec import srgb
from wrinklepipe.metrics import DECIMALS, Budget, angle_deg, delta_e, weighted_stats
from wrinklepipe.names import noun, plural
from wrinklepipe.palette import region_colours_linear
from wrinklepipe.shading.setup import ShaderSetup
from wrinklepipe.validate import fidelity_pictures as fp
from wrinklepipe.validate import gl as glw
from wrinklepipe.validate import textures as tx
from wrinklepipe.validate.catalogue import Issue, make_issue
from wrinklepipe.validate.context import Context
from wrinklepipe.validate.inputs import Texture
from wrinklepipe.validate.poses import render_poses
from wrinklepipe.validate.renderer import (
    Frame,
    Renderer,
    color_textures,
    mask_layers,
    shader_setup,
    split_part,
)
from wrinklepipe.validate.rules_fidelity import render_fidelity

#: WP-RND-003 judges an expression only where its strongly active pixels are more than this share
#: of the render target (50 pixels at 512^2, as it was before the size followed the maps), so a
#: smaller target asks for the same screen area, not for more of it.
MIN_STRONG_SHARE = 50.0 / 512**2


def shade_albedo(n_obj: np.ndarray, albedo: np.ndarray) -> np.ndarray:
    """``shaders/color.glsl``'s lighting in numpy: the key light, ambient and Blinn specular on
    ``albedo`` (linear), for object-space normals ``n_obj`` ``[N, 3]`` (float32 arithmetic)."""
    f = np.float32
    light = np.array([-0.3713907, 0.5570860, 0.7427813], f)
    half = light + np.array([0.0, 0.0, 1.0], f)
    half /= np.sqrt(np.dot(half, half))
    n = np.asarray(n_obj, f)
    diffuse = np.maximum(n @ light, f(0.0))
    spec = np.maximum(n @ half, f(0.0)) ** f(48.0) * f(0.25)
    return (np.asarray(albedo, f) * (f(0.12) + f(0.88) * diffuse)[:, None] + spec[:, None]).astype(
        f
    )


# ------------------------------------------------------------------------------------------------
# numpy reference at the rasterised UVs


@dataclass
class Samples:
    """Shipped (and source) data sampled at the covered pixels' UVs, shared by all poses."""

    base: np.ndarray  # [N, 3]
    states: np.ndarray  # [K, N, C]
    masks: np.ndarray  # [R, N] shipped
    src_masks: np.ndarray | None  # [R, N]
    src_relief: np.ndarray | None  # [K, N] degrees between source state and base


def sample_reference(ctx: Context, uv: np.ndarray) -> Samples:
    inp, a = ctx.inp, ctx.asset
    bt = ctx.base_tex
    # filter the stored values, then decode (as the sampler and the shader do)
    base = tx.values_to_normals(ctx.sample_values(bt, uv), tx.xy_layout(bt), ctx.flips(bt))
    states = []
    for t in inp.state_textures():
        v = ctx.sample_values(t, uv)
        states.append(
            tx.decode_state(
                v, a.encoding, tx.xy_layout(t), a.pd_scale, t.mapping, t.bits, ctx.flips(t)
            )
        )
    sampled: dict[str, np.ndarray] = {}
    masks = []
    by_region = {e.region: e for e in inp.channel_table}

    def sample(name: str) -> np.ndarray:
        if name not in sampled:
            sampled[name] = tx.bilinear(ctx.values(inp.texture(name)), uv)
        return sampled[name]

    for r in a.region_names:
        e = by_region[r]
        m = sample(e.texture)[:, e.channel]
        part = split_part(e)
        if part:
            s = sample(e.split[0])[:, e.split[1]]
            m = m * s if part == 1 else m * (1.0 - s)
        masks.append(m)
    src_masks = src_relief = None
    if not inp.has_source and states:
        # no source: the relief each shipped state adds at full activation
        rel = []
        for k in range(len(states)):
            w = model.combine(base, states[k][None], np.ones((1, len(uv)), np.float32), a.encoding)
            rel.append(angle_deg(w, base))
        src_relief = np.stack(rel)
    src = ctx.source_at_shipped_size
    if src is not None:
        # the source at the shipped sizes: resolution choices are WP-TEX-006's business
        src_masks = tx.bilinear_planes(src["masks"], uv).T
        b = model.normalize(tx.bilinear(src["base_at_states"], uv))
        rel = []
        for s in src["states"]:
            w = model.normalize(tx.bilinear(s, uv))
            rel.append(angle_deg(w, b))
        src_relief = np.stack(rel) if rel else None
    return Samples(base, np.stack(states), np.stack(masks), src_masks, src_relief)


def _compare_colors(
    ctx: Context,
    setup: ShaderSetup,
    uv: np.ndarray,
    cov: np.ndarray,
    frames: dict[str, Frame],
    by_name: dict[str, Any],
    samples: Samples,
    info: dict[str, Any],
    where: str,
) -> list[Issue]:
    """The GPU's albedo and lit colour against the numpy colour model of the same shipped
    texels, in CIEDE2000 (WP-RND-005)."""
    colors = color_textures(ctx.inp)
    if colors is None:
        return []
    factor = np.asarray(ctx.inp.extra.get("color_factor", (1.0, 1.0, 1.0)), np.float32)

    def linear(t: Texture) -> np.ndarray | None:
        q = ctx.texels(t)
        return None if q is None else srgb.decode_texels(q[..., :3])

    base_lin = linear(colors[0])
    states_lin = [linear(t) for _, t in colors[1]]
    if base_lin is None or any(s is None for s in states_lin):
        return []
    # decode each texel, then filter (an sRGB sampler); the factor after (it is linear)
    cb = tx.bilinear(base_lin, uv) * factor
    cs = np.stack([tx.bilinear(s, uv) for s in states_lin])
    a = ctx.asset
    per_pose: dict[str, Any] = {}
    worst: tuple[str, float] | None = None
    limit = ctx.options.gpu_max_p99_delta_e
    for label, fr in frames.items():
        if fr.albedo is None or fr.object_normal is None:
            continue
        act = model.activations(samples.masks, by_name[label].weights, a.policy)
        albedo = model.combine_color(cb, cs, act[list(setup.color_states)])
        gpu_albedo = fr.albedo[cov][:, :3]
        n_obj = fr.object_normal[cov][:, :3]
        lit = np.clip(shade_albedo(n_obj, albedo), 0.0, 1.0)
        gpu_lit = np.clip(fr.color[cov][:, :3], 0.0, 1.0)
        st = {
            "albedo": _stats(delta_e(gpu_albedo, albedo).astype(np.float32)),
            "lit": _stats(delta_e(gpu_lit, lit).astype(np.float32)),
        }
        per_pose[label] = st
        p99 = max(st["albedo"]["p99"], st["lit"]["p99"])
        if p99 > limit and (worst is None or p99 > worst[1]):
            worst = (label, p99)
    info["color_vs_reference_delta_e"] = per_pose
    ctx.metrics["gpu_vs_reference_delta_e"] = per_pose
    if worst is None:
        return []
    bad = [k for k, v in per_pose.items() if max(v["albedo"]["p99"], v["lit"]["p99"]) > limit]
    return [
        make_issue(
            "WP-RND-005",
            f"{len(bad)} of {len(per_pose)} poses: the GPU's colour (albedo or lit) differs from "
            f"the numpy colour model of the same bytes by p99 over {limit:g} CIEDE2000; worst "
            f"{worst[0]}: p99 {worst[1]:.2f}",
            where,
        )
    ]


def _stats(e: np.ndarray) -> dict[str, float]:
    """The one measure's statistics of per-pixel errors, as the metrics tables show them."""
    s = weighted_stats(e)
    return {
        "mean": round(s.mean, DECIMALS),
        "p99": round(s.p99, DECIMALS),
        "max": round(s.max, DECIMALS),
    }


def _skip(reason: str, where: str) -> tuple[list[Issue], dict[str, Any], dict[str, Any]]:
    return (
        [make_issue("WP-RND-004", f"render pass skipped: {reason}", where)],
        {"skipped": reason},
        {},
    )


def can_render(ctx: Context) -> str:
    """Empty when the render pass can run on this input, else the reason it cannot."""
    inp, a = ctx.inp, ctx.asset
    if a.mesh is None or a.mesh.uvs is None:
        return "no mesh with UVs"
    if not a.regions or not a.state_names:
        return "no regions or no states"
    if a.encoding not in model.ENCODINGS or a.policy not in model.POLICIES:
        return "unknown encoding or policy"
    if a.policy == "signed" and len(a.state_names) != 2:
        return "policy 'signed' needs two states"
    if not inp.by_role("base") or not ctx.decodable(ctx.base_tex):
        return "no decodable base texture"
    sts = inp.state_textures()
    if not sts or any(t is None or not ctx.decodable(t) for t in sts):
        return "a state texture is missing or undecodable"
    if len({(t.fmt, t.width, t.height, t.convention) for t in sts}) > 1:
        return "state textures differ in size, format or declared convention"
    if ctx.shipped_masks is None:
        return "the channel table or mask textures are unusable"
    splits = {e.split for e in inp.channel_table if e.split is not None}
    if len(splits) > 1:
        return "more than one split channel (lr-split layout)"
    layers = mask_layers(inp)
    if len({(t.fmt, t.width, t.height) for t in layers}) > 1:
        return "mask textures differ in size or format"
    problems = shader_setup(inp).problems()
    if problems:
        return "; ".join(problems)
    for t in [ctx.base_tex, *sts, *layers]:
        if t.is_block and (t.width % 4 or t.height % 4):
            return f"{t.name!r} is block-compressed with a size that is not a multiple of 4"
    return ""


def render_pass(ctx: Context) -> tuple[list[Issue], dict[str, Any], dict[str, Any]]:
    """Render the poses the drivers produce (:func:`render_poses`); returns (issues, render
    info, images)."""
    inp, a, o = ctx.inp, ctx.asset, ctx.options
    where = inp.pointer("meta")
    reason = can_render(ctx)
    if reason:
        return _skip(reason, where)
    try:
        r = Renderer(inp, ctx.render_size)
    except glw.GLUnavailable as exc:
        return _skip(str(exc), where)
    except Exception as exc:  # noqa: BLE001 - a driver refusing a shader or format
        return _skip(f"{type(exc).__name__}: {str(exc).strip()[:300]}", where)
    images: dict[str, Any] = {}
    issues: list[Issue] = []
    info = dict(r.info)
    poses = render_poses(inp)
    by_name = {p.name: p for p in poses}
    info["pose_sources"] = {
        p.name: {"curve": p.curve, "time": p.time, "regions": list(p.regions), "morphs": p.morphs}
        for p in poses
        if p.curve is not None
    }
    try:
        t0 = time.perf_counter()
        frames = {}
        for pose in poses:  # the UVs are read once (the neutral pose's)
            frames[pose.name] = r.draw(pose.weights, uv=pose.name == "neutral")
        info["render_s"] = round(time.perf_counter() - t0, 4)
        plain = r.draw(None, plain=True, color=False, uv=False)
    except Exception as exc:  # noqa: BLE001 - a driver failing mid-draw: report, do not crash
        return _skip(f"{type(exc).__name__}: {str(exc).strip()[:300]}", where)
    finally:
        r.release()
    t0 = time.perf_counter()
    neutral = frames["neutral"]
    cov = neutral.covered
    if not cov.any():
        return _skip("the mesh covers no pixel of the render target", where)
    uv = neutral.uv[cov][:, :2]
    samples = sample_reference(ctx, uv)
    per_pose: dict[str, Any] = {}
    gpu_bad = []
    leaks = []
    missing = []
    n_gpu_neutral = neutral.normal[cov][:, :3]
    min_strong = MIN_STRONG_SHARE * cov.size
    for label, fr in frames.items():
        w = by_name[label].weights
        ref = model.blend(samples.base, samples.states, samples.masks, w, a.encoding, a.policy)
        gpu = fr.normal[cov][:, :3]
        err = angle_deg(gpu, ref)
        st = _stats(err)
        entry: dict[str, Any] = {"gpu_vs_reference_deg": st}
        if not Budget(o.gpu_max_mean_deg, o.gpu_max_p99_deg).ok(weighted_stats(err)):
            gpu_bad.append((label, st))
        emap = np.zeros(cov.shape, np.float32)
        emap[cov] = err
        images[f"gpu_error/{label}"] = emap
        images[f"render/{label}"] = fr.color[..., :3]
        if label != "neutral":
            change, leaked, quiet = _change_from_neutral(
                ctx, samples, cov, gpu, n_gpu_neutral, w, min_strong, entry
            )
            if leaked is not None:
                leaks.append((label, leaked))
            if quiet is not None:
                missing.append((label, *quiet))
            cmap = np.zeros(cov.shape, np.float32)
            cmap[cov] = change
            images[f"change/{label}"] = cmap
        per_pose[label] = entry
    if r.setup.has_color:
        issues += _compare_colors(ctx, r.setup, uv, cov, frames, by_name, samples, info, where)
    plain_err = angle_deg(plain.normal[cov][:, :3], samples.base)
    info["plain_vs_reference_deg"] = _stats(plain_err)
    info["covered_pixels"] = int(cov.sum())
    info["poses"] = per_pose
    info["compare_s"] = round(time.perf_counter() - t0, 4)
    ctx.metrics["gpu_vs_reference_deg"] = {
        k: v["gpu_vs_reference_deg"] for k, v in per_pose.items()
    }
    issues += _fidelity_render(ctx, uv, cov, frames, samples, images)
    _overlay_and_crop(len(a.regions), cov, samples, neutral, images, info)
    if gpu_bad:
        worst = max(gpu_bad, key=lambda x: x[1]["p99"])
        issues.append(
            make_issue(
                "WP-RND-001",
                f"{len(gpu_bad)} of {len(frames)} poses: GPU normal buffer vs numpy reference "
                f"over {o.gpu_max_mean_deg:g} mean / {o.gpu_max_p99_deg:g} p99 degrees; worst "
                f"{worst[0]}: mean {worst[1]['mean']:.2f}, p99 {worst[1]['p99']:.2f}",
                where,
            )
        )
    if leaks:
        worst = max(leaks, key=lambda x: x[1])
        issues.append(
            make_issue(
                "WP-RND-002",
                f"{plural(len(leaks), 'expression')} {noun(len(leaks), 'changes', 'change')} the "
                f"render where masks x weights are zero; worst {worst[0]}: {worst[1]} pixels",
                inp.pointer("masks"),
            )
        )
    if missing:
        worst = max(missing, key=lambda x: x[1] / x[2])
        issues.append(
            make_issue(
                "WP-RND-003",
                f"{plural(len(missing), 'expression')} {noun(len(missing), 'shows', 'show')} no "
                f"wrinkle where the source is fully active; worst {worst[0]}: {worst[1]} of "
                f"{worst[2]} pixels unchanged",
                inp.pointer("masks"),
            )
        )
    return issues, info, images


def _change_from_neutral(
    ctx: Context,
    samples: Samples,
    cov: np.ndarray,
    gpu: np.ndarray,
    n_gpu_neutral: np.ndarray,
    w: np.ndarray,
    min_strong: float,
    entry: dict[str, Any],
) -> tuple[np.ndarray, int | None, tuple[int, int] | None]:
    """An expression's change from the neutral render (degrees per covered pixel); the pixels
    it changes where masks x weights are zero, when more than ``leak_fraction`` (WP-RND-002);
    (quiet, strong) pixels when it leaves the source's strongly active pixels unchanged
    (WP-RND-003). Counts go into ``entry``."""
    o, a = ctx.options, ctx.asset
    change = angle_deg(gpu, n_gpu_neutral)
    changed = change > o.wrinkle_deg
    masks_expected = samples.src_masks if samples.src_masks is not None else samples.masks
    act = model.activations(masks_expected, w, a.policy)
    active = np.abs(act).sum(axis=0) > 1e-4
    act_img = np.zeros(cov.shape, bool)
    act_img[cov] = active
    act_img = ndimage.binary_dilation(act_img, np.ones((5, 5), bool), iterations=2)
    leak = changed & ~act_img[cov]
    n_leak = int(leak.sum())
    entry["changed_pixels"] = int(changed.sum())
    entry["leak_pixels"] = n_leak
    leaked = n_leak if n_leak > o.leak_fraction * cov.sum() else None
    quiet_strong = None
    if samples.src_relief is not None and len(samples.src_relief) == len(act):
        k_rel = samples.src_relief
        full_act = act > 0.5
        strong = (full_act & (k_rel > 4.0 * o.wrinkle_deg)).any(axis=0)
        quiet = strong & (change < 0.5 * o.wrinkle_deg)
        entry["strong_pixels"] = int(strong.sum())
        entry["quiet_pixels"] = int(quiet.sum())
        if strong.sum() > min_strong and quiet.sum() > 0.25 * strong.sum():
            quiet_strong = (int(quiet.sum()), int(strong.sum()))
    return change, leaked, quiet_strong


def _fidelity_render(
    ctx: Context,
    uv: np.ndarray,
    cov: np.ndarray,
    frames: dict[str, Frame],
    samples: Samples,
    images: dict[str, Any],
) -> list[Issue]:
    """Fidelity in screen space: the GPU render against the full-resolution source's; its
    error maps and the two renders' normals go into ``images``."""
    gpu = {e: fr.normal[cov][:, :3] for e, fr in frames.items() if e is not None}
    f_issues, f_info = render_fidelity(ctx, uv, gpu, samples.masks)
    for e, err in f_info.get("maps", {}).items():
        emap = np.zeros(cov.shape, np.float32)
        emap[cov] = err
        images[f"fidelity_render/{e}"] = emap
        # the full-resolution source's render beside the shipped one: blended normals per pixel
        for key, n in (("render_source", f_info["normals"][e]), ("render_shipped", gpu[e])):
            pic = np.ones(cov.shape + (3,), np.float32)
            pic[cov] = fp.normal_picture(n)
            images[f"{key}/{e}"] = pic
    return f_issues


def _overlay_and_crop(
    n_regions: int,
    cov: np.ndarray,
    samples: Samples,
    neutral: Frame,
    images: dict[str, Any],
    info: dict[str, Any],
) -> None:
    """The mask overlay (shipped masks coloured per region over the neutral render, from the
    UV buffer) and the contact sheet cropped to the masked area (with a margin, square)."""
    overlay = np.zeros(cov.shape + (3,), np.float32)
    colors = region_colours_linear(n_regions)  # Tol's colour-blind-safe schemes
    overlay[cov] = np.clip(samples.masks.T @ colors, 0.0, 1.0)
    images["mask_overlay"] = 0.5 * neutral.color[..., :3] + 0.5 * overlay
    images["_region_colors"] = colors
    union = np.zeros(cov.shape, bool)
    union[cov] = samples.masks.max(axis=0) > 1.0 / 255.0
    if union.any():
        ys, xs = np.nonzero(union)
        cy, cx = (ys.min() + ys.max()) / 2, (xs.min() + xs.max()) / 2
        half = int(max(ys.max() - ys.min(), xs.max() - xs.min()) * 0.6) + 4
        y0, x0 = max(int(cy) - half, 0), max(int(cx) - half, 0)
        y1, x1 = min(int(cy) + half, cov.shape[0]), min(int(cx) + half, cov.shape[1])
        info["crop"] = [int(x0), int(y0), int(x1), int(y1)]
        for k in list(images):
            if k.split("/")[0] in (
                "render",
                "gpu_error",
                "change",
                "fidelity_render",
                "render_source",
                "render_shipped",
            ):
                images[k] = images[k][y0:y1, x0:x1]
