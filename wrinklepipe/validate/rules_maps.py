"""Rules on declarations and on the normal / wrinkle maps (WP-LOAD-*, WP-MAP-*)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from wrinklepipe import codec, model
from wrinklepipe.codec.vectors import EPS
from wrinklepipe.metrics import angle_deg, weighted_stats
from wrinklepipe.validate import textures as tx
from wrinklepipe.validate.catalogue import Issue, make_issue
from wrinklepipe.validate.context import Context
from wrinklepipe.validate.inputs import Texture
from wrinklepipe.workset import band_rows


def check_declarations(ctx: Context) -> list[Issue]:
    a, inp = ctx.asset, ctx.inp
    out: list[Issue] = []
    where = inp.pointer("meta")
    if a.encoding not in model.ENCODINGS:
        out.append(make_issue("WP-LOAD-001", f"unknown encoding {a.encoding!r}", where))
    if a.policy not in model.POLICIES:
        out.append(make_issue("WP-LOAD-001", f"unknown policy {a.policy!r}", where))
    elif a.policy == "signed" and len(a.state_names) != 2:
        out.append(
            make_issue(
                "WP-LOAD-001",
                f"policy 'signed' needs exactly 2 states, the asset has {len(a.state_names)}",
                where,
            )
        )
    if not a.state_names or not a.regions:
        what = "no wrinkle states" if not a.state_names else "no regions"
        out.append(make_issue("WP-LOAD-003", f"the asset declares {what}", where))
    if inp.textures:
        sts = inp.state_textures()
        for name, t in zip(a.state_names, sts):
            if t is None:
                out.append(
                    make_issue("WP-LOAD-002", f"state {name!r} has no shipped texture", where)
                )
        present = [t for t in sts if t is not None]
        if len({(t.fmt, t.width, t.height) for t in present}) > 1:
            desc = ", ".join(f"{t.state}: {t.fmt} {t.width}x{t.height}" for t in present)
            out.append(
                make_issue(
                    "WP-LOAD-002", f"state textures differ in size or format ({desc})", where
                )
            )
    return out


# ------------------------------------------------------------------------------------------------
# green convention: integrability (curl) of the slope field


def convention_score(slopes: np.ndarray, weight: np.ndarray | None = None) -> float:
    """+1 when PD slopes ``[H, W, 2]`` are integrable with +Y up (OpenGL), -1 when only with
    green flipped (DirectX), near 0 when the map has no relief to tell.

    With ``px = -dh/dcol`` and ``py = +dh/drow`` (rows run down, +Y up) the mixed derivatives
    satisfy ``d(px)/drow = -d(py)/dcol``; the score is the normalised correlation of the two.
    """
    s = np.asarray(slopes)
    if s.ndim != 3 or s.shape[0] < 3 or s.shape[1] < 3:
        return 0.0
    return _curl_score(lambda c, r0, r1: s[r0:r1, :, c], s.shape[:2], weight)


def normals_convention_score(normals: np.ndarray) -> float:
    """:func:`convention_score` of the PD slopes of unit normals ``[H, W, 3]``
    (:func:`wrinklepipe.model.normal_to_pd`'s float32 operations), a slope channel and a band
    of rows at a time: the same score, without the slopes of both channels and their float64
    copy at once."""
    n = np.asarray(normals, np.float32)
    if n.ndim != 3:
        return 0.0
    return normal_rows_convention_score(lambda r0, r1: n[r0:r1], n.shape[:2])


def normal_rows_convention_score(
    rows: Callable[[int, int], np.ndarray], shape: tuple[int, ...]
) -> float:
    """:func:`normals_convention_score` of the ``shape`` (``[H, W]``) map of unit normals whose
    rows ``r0:r1`` are ``rows(r0, r1)`` (e.g. decoded from their texels there: the map is
    never whole)."""
    if shape[0] < 3 or shape[1] < 3:
        return 0.0

    def slope(c: int, r0: int, r1: int) -> np.ndarray:
        n = np.asarray(rows(r0, r1), np.float32)
        return n[..., c] * np.reciprocal(np.maximum(n[..., 2], EPS))

    return _curl_score(slope, shape, None)


#: Bytes of temporaries per texel of a band of the curl score (float32 slopes, their float64
#: copies, gradients and products).
CURL_BYTES = 64


#: numpy's pairwise summation sums blocks of at most this many values without splitting them.
PAIRWISE_BLOCK = 128


def _gradient_rows(
    channel: Callable[[int, int, int], np.ndarray], c: int, h: int, axis: int, r0: int, r1: int
) -> np.ndarray:
    """Rows ``r0:r1`` of ``np.gradient(channel c in float64, axis=axis)`` of the ``[h, W]``
    slope channel whose rows ``r0:r1`` are ``channel(c, r0, r1)``: made from those rows and the
    row on either side of them (numpy's central and edge differences are per texel, so the
    whole channel's values)."""
    lo, hi = (max(r0 - 1, 0), min(r1 + 1, h)) if axis == 0 else (r0, r1)
    g = np.gradient(np.asarray(channel(c, lo, hi), np.float64), axis=axis)
    return g[r0 - lo : r1 - lo]


def _pairwise_sums(
    n: int, leaf: Callable[[int, int], tuple[np.ndarray, ...]], limit: int, lo: int = 0
) -> tuple[np.float64, ...]:
    """``np.sum`` of each of several contiguous float64 arrays of ``n`` values whose flat
    values ``lo:hi`` are ``leaf(lo, hi)``, bit for bit, without the arrays: numpy sums a
    contiguous array pairwise (halves rounded down to a multiple of 8, down to blocks of 128),
    so this splits the same way down to pieces of at most ``limit`` values and sums each with
    numpy (a piece's pairwise sum; ``-0.0`` is the exact identity) and the halves as numpy adds
    them. The whole sum is numpy's ``0.0 + pairwise(all)``: the caller adds the ``0.0``."""
    if n <= max(limit, PAIRWISE_BLOCK):  # numpy splits no block of 128 values or fewer
        return tuple(np.add.reduce(x, initial=-0.0) for x in leaf(lo, lo + n))
    n2 = n // 2
    n2 -= n2 % 8
    left = _pairwise_sums(n2, leaf, limit, lo)
    right = _pairwise_sums(n - n2, leaf, limit, lo + n2)
    return tuple(x + y for x, y in zip(left, right, strict=True))


def _curl_score(
    channel: Callable[[int, int, int], np.ndarray],
    shape: tuple[int, ...],
    weight: np.ndarray | None,
) -> float:
    """The score of slopes whose channel ``c``, rows ``r0:r1``, is ``channel(c, r0, r1)``:
    ``-sum(a b) / sqrt(sum(a a) sum(b b))`` of the gradients ``a`` (channel 0 down the rows) and
    ``b`` (channel 1 along them), weighted, as numpy's whole-array sums give it bit for bit
    (:func:`_pairwise_sums`), with the gradients of a band of rows at a time (no float64
    gradients or products of the whole map: 2 GiB at 8192²)."""
    h, w = int(shape[0]), int(shape[1])
    wt = None if weight is None else np.asarray(weight)

    def products(lo: int, hi: int) -> tuple[np.ndarray, ...]:
        r0, r1 = lo // w, (hi - 1) // w + 1
        a = _gradient_rows(channel, 0, h, 0, r0, r1)
        b = _gradient_rows(channel, 1, h, 1, r0, r1)
        if wt is not None:
            a, b = a * wt[r0:r1], b * wt[r0:r1]
        a = a.reshape(-1)[lo - r0 * w : hi - r0 * w]
        b = b.reshape(-1)[lo - r0 * w : hi - r0 * w]
        return a * b, a * a, b * b

    limit = band_rows(w, CURL_BYTES) * w
    ab, aa, bb = (0.0 + s for s in _pairwise_sums(h * w, products, limit))
    den = np.sqrt(aa * bb)
    if not np.isfinite(den) or den < 1e-12:
        return 0.0
    return float(-ab / den)


def _state_slopes(ctx: Context, k: int, state: np.ndarray) -> np.ndarray | None:
    """Slopes of what a state map holds (the wrinkle, or the wrinkled face) for the curl test."""
    enc = ctx.asset.encoding
    if enc == "pd":
        return state
    if enc in ("full", "composite"):
        return model.normal_to_pd(state)
    base = ctx.shipped_base
    if base is None:
        return None
    if base.shape[:2] != state.shape[:2]:
        base = tx.resize_bilinear(base, *state.shape[:2])
    return model.normal_to_pd(model.normalize(base + model.diff_to_delta(state)))


#: Bytes of temporaries per texel of the unit-length and z checks (float32 values, raw
#: normals, their squares and lengths, flags).
CHECK_BYTES = 64


def _texel_counts(
    values: np.ndarray, tol: float, read: Callable[[np.ndarray], np.ndarray] | None = None
) -> tuple[int, int, int, int | None, int | None]:
    """Over a three-channel normal map's texels (stored ``values`` ``[H, W, C]``, or texels
    ``read`` turns into them, per texel): the counts of texels NaN or not unit, NaN, z < 0, and
    the flat index of the first texel not unit and of the first with z < 0. Band by band of
    rows: every test is per texel, so the counts and indices of the whole map at once."""
    h, w = values.shape[:2]
    rows = band_rows(w, CHECK_BYTES)
    n_bad = n_nan = n_neg = 0
    first_bad: int | None = None
    first_neg: int | None = None
    for r0 in range(0, h, rows):
        v = values[r0 : r0 + rows]
        n = tx.raw_normals(v if read is None else read(v), "rgb").reshape(-1, 3)
        nan = ~np.isfinite(n).all(axis=1)
        length = np.linalg.norm(np.nan_to_num(n), axis=1)
        bad = nan | (np.abs(length - 1.0) > tol)
        neg = np.nan_to_num(n[:, 2]) < 0
        if first_bad is None and bad.any():
            first_bad = r0 * w + int(np.flatnonzero(bad)[0])
        if first_neg is None and neg.any():
            first_neg = r0 * w + int(np.flatnonzero(neg)[0])
        n_bad += int(bad.sum())
        n_nan += int(nan.sum())
        n_neg += int(neg.sum())
    return n_bad, n_nan, n_neg, first_bad, first_neg


def _normal_map_texture_checks(
    ctx: Context,
    t: Texture,
    values: np.ndarray,
    read: Callable[[np.ndarray], np.ndarray] | None = None,
) -> list[Issue]:
    """Unit length and z >= 0 of a three-channel normal map's stored ``values`` (or of the
    texels ``read`` turns into them)."""
    o = ctx.options
    out = []
    tol = o.unit_tolerance
    n_bad, n_nan, n_neg, first_bad, first_neg = _texel_counts(values, tol, read)
    total = max(values.shape[0] * values.shape[1], 1)
    if n_bad > o.max_bad_fraction * total:
        first = int(first_bad)  # type: ignore[arg-type]
        out.append(
            make_issue(
                "WP-MAP-001",
                f"{n_bad} of {total} texels are NaN ({n_nan}) or not unit "
                f"(| |n| - 1 | > {tol}); first at texel ({first % t.width}, {first // t.width})",
                t.where,
                texels=n_bad,
            )
        )
    if n_neg > o.max_bad_fraction * total:
        first = int(first_neg)  # type: ignore[arg-type]
        out.append(
            make_issue(
                "WP-MAP-002",
                f"{n_neg} of {total} texels have z < 0; first at texel "
                f"({first % t.width}, {first // t.width})",
                t.where,
                texels=n_neg,
            )
        )
    return out


def _convention_issue(ctx: Context, t: Texture, score: float) -> Issue | None:
    """WP-MAP-003 of a map whose slopes score ``score`` (:func:`convention_score`)."""
    ctx.metrics.setdefault("convention_score", {})[t.name] = round(score, 4)
    # the slopes were read as declared (context.values flips a DirectX map), so a negative
    # score means the map is in the other convention than declared
    declared = t.convention if t.convention in ("opengl", "directx") else "opengl"
    other = "directx" if declared == "opengl" else "opengl"
    detected = declared if score > 0.25 else other if score < -0.25 else "undetermined"
    if detected not in ("undetermined", declared):
        return make_issue(
            "WP-MAP-003",
            f"declared {declared} (+Y {'up' if declared == 'opengl' else 'down'}) but the slopes "
            f"are integrable only as {detected} (curl score {score:+.2f}): green is flipped",
            t.where,
            score=round(score, 3),
        )
    return None


def check_maps(ctx: Context) -> list[Issue]:
    a = ctx.asset
    o = ctx.options
    out: list[Issue] = []
    bt = ctx.base_tex
    if bt is not None and ctx.decodable(bt):
        layout = tx.xy_layout(bt)
        if layout == "rgb":  # the base's values from its texels, band by band (not held)
            out += _normal_map_texture_checks(ctx, bt, ctx.texels(bt), tx.unorm_values)
        shipped = ctx.shipped_base_texels()
        if shipped is not None:  # its normals decoded a band of rows at a time (not held)
            q, store = shipped[0], shipped[1].store
            h, w = q.shape[:2]

            def rows(r0: int, r1: int) -> np.ndarray:
                return store(q[r0:r1].reshape((r1 - r0) * w, -1)).reshape(r1 - r0, w, 3)

            issue = _convention_issue(ctx, bt, normal_rows_convention_score(rows, (h, w)))
            if issue:
                out.append(issue)
    states = ctx.shipped_states
    texs = ctx.inp.state_textures()
    if states is None:
        return out
    for k, (t, st) in enumerate(zip(texs, states)):
        v = ctx.values(t)
        layout = tx.xy_layout(t)
        if a.encoding in ("full", "composite") and layout == "rgb":
            out += _normal_map_texture_checks(ctx, t, v)
        slopes = _state_slopes(ctx, k, st)
        if slopes is not None:
            issue = _convention_issue(ctx, t, convention_score(slopes))
            if issue:
                out.append(issue)
        if a.encoding == "pd":
            # texels at the edge of the cone: |t| within half a step of 1
            half = 0.5 / codec.mapping(t.mapping).centre(t.bits or 8)[1]
            xy = v[..., list(codec.layout(layout).components[:2])]  # DXT5nm: x in A
            edge = np.abs(tx.signed_values(xy, t, "pd")) >= 1.0 - half
            clipped = int(edge.any(axis=-1).sum())
            lossless = ctx.inp.extra.get("pd_edge_texels", {})
            if t.is_block and t.name in lossless:  # one count: the stored (PNG) texels'
                clipped = int(lossless[t.name])
            total = v.shape[0] * v.shape[1]
            ctx.metrics.setdefault("pd_clipped_texels", {})[t.name] = clipped
            if clipped > o.max_clipped_fraction * total:
                out.append(
                    make_issue(
                        "WP-MAP-004",
                        f"{clipped} of {total} texels ({100.0 * clipped / total:.2f}%) sit at the "
                        f"edge of the recorded cone (pd_scale {a.pd_scale:g}, "
                        f"{np.degrees(np.arctan(a.pd_scale)):.1f} degrees): slopes were clipped",
                        t.where,
                        texels=clipped,
                    )
                )
        if a.encoding == "diff" and v.shape[-1] >= 3:
            # the median delta of a difference map is 0 (most of a face does not wrinkle)
            h = codec.mapping(t.mapping).centre(t.bits or 8)[1]
            med_t = np.median(tx.signed_values(v[..., :3], t, "diff").reshape(-1, 3), axis=0)
            med = np.median(v[..., :3].reshape(-1, 3), axis=0)
            if np.abs(med_t).max() > 2.0 / h:
                centre = codec.mapping(t.mapping).centre(t.bits or 8)[0] / (
                    (1 << (t.bits or 8)) - 1
                )
                out.append(
                    make_issue(
                        "WP-MAP-005",
                        "median stored value is ("
                        + ", ".join(f"{x:.3f}" for x in med)
                        + f"), expected {centre:.3f} (off by {np.abs(med_t).max() * h:.1f}"
                        f"/{(1 << (t.bits or 8)) - 1})",
                        t.where,
                    )
                )
    out += _encoding_match(ctx)
    return out


# ------------------------------------------------------------------------------------------------
# does the content fit the declared encoding? (needs the source)


def _as_full(
    enc: str, base: np.ndarray, values: np.ndarray, t: Texture, scale: float
) -> np.ndarray:
    """The wrinkled face the stored values mean if they were ``enc`` (the codec's decode)."""
    e = codec.encoding(enc)
    x = tx.decode_state(values, enc, tx.xy_layout(t), scale, t.mapping, t.bits, Context.flips(t))
    if enc == "diff":
        x = model.diff_to_delta(x)
    return e.to_normal(x, base)


def _encoding_match(ctx: Context) -> list[Issue]:
    a, inp = ctx.asset, ctx.inp
    if not inp.has_source or not ctx.has_shipped_base or a.encoding not in model.ENCODINGS:
        return []
    out = []
    for k, t in enumerate(inp.state_textures()):
        v = ctx.values(t) if t is not None else None
        if v is None or k >= len(a.states):
            continue
        h, w = v.shape[:2]
        ref = ctx.source_at_shipped_size
        if ref is None or ref["states"].shape[1:3] != (h, w):
            continue
        src = ref["states"][k]
        # judge on the texels that carry a wrinkle (elsewhere every encoding decodes to B)
        src_base = ref["base_at_states"]
        relief = angle_deg(src, src_base) > 2.0
        if relief.sum() < 16:
            continue
        # decoding is per texel: decode the wrinkled texels only, as a [1, n] image (the
        # shipped base at the state's size at those texels only: no decoded or resampled map)
        base_r = ctx.shipped_base_at(h, w, relief)
        if base_r is None:
            continue
        v_r, base_r, src_r = v[relief][None], base_r[None], src[relief]
        errs = {}
        for enc in model.ENCODINGS:
            if enc == "diff" and v.shape[-1] < 3:
                continue
            full = _as_full(enc, base_r, v_r, t, a.pd_scale)[0]
            errs[enc] = weighted_stats(angle_deg(full, src_r)).mean
        ctx.metrics.setdefault("encoding_fit_mean_deg", {})[t.name] = {
            e: round(x, 3) for e, x in errs.items()
        }
        declared = errs.get(a.encoding, np.inf)
        best = min(errs, key=errs.get)
        if best != a.encoding and declared > 1.0 and declared > 3.0 * errs[best]:
            out.append(
                make_issue(
                    "WP-MAP-006",
                    f"state {t.state!r} decoded as {a.encoding} is {declared:.2f} degrees (mean "
                    f"over wrinkled texels) from the source; decoded as {best} it is "
                    f"{errs[best]:.2f}: it looks like a {best} map",
                    t.where,
                    fix=f"Declare encoding = {best!r}, or re-encode the map as {a.encoding}.",
                )
            )
    return out
