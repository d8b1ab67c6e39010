"""Pictures of the fidelity measure for the validator's HTML page (numpy only).

Per pose, cropped to the wrinkled area (the texels the pose activates in the source, with a
margin, square), on the source grid:

- ``fidelity_source/<pose>``: the full-resolution source's blended normal map (``0.5 + 0.5 n``),
- ``fidelity_shipped/<pose>``: the shipped maps' (decoded, magnified as a GPU samples them),
- ``fidelity_error/<pose>``: the measure's angular error in degrees where the pose is active
  (the texels it judges, leaks included; 0 elsewhere), shown as a heat map with a colour bar;

and per region ``region_mask/<region>``: the shipped mask as grey levels (0 black, 1 white, opaque:
visible whatever channel it is packed in). A crop larger than :data:`CROP_MAX` texels keeps
every k-th texel (nearest), so no picture is larger than that.
"""

from __future__ import annotations

import numpy as np

from wrinklepipe import fidelity as fd
from wrinklepipe import model
from wrinklepipe.fidelity.sampling import Reader

_F = np.float32

#: Largest side of a picture, in texels.
CROP_MAX = 512
#: Texels added around the active area of a pose.
MARGIN = 4


def crop_box(flat: np.ndarray, shape: tuple[int, int], margin: int = MARGIN) -> tuple[int, ...]:
    """``(y0, y1, x0, x1)``: the square around texels ``flat`` of a ``shape`` grid, widened by
    ``margin`` and kept inside the grid (the whole grid when ``flat`` is empty)."""
    H, W = shape
    if flat.size == 0:
        return 0, H, 0, W
    ys, xs = flat // W, flat % W
    side = int(max(ys.max() - ys.min(), xs.max() - xs.min())) + 1 + 2 * margin
    side = min(side, H, W)
    cy, cx = (int(ys.min()) + int(ys.max())) // 2, (int(xs.min()) + int(xs.max())) // 2
    y0 = min(max(cy - side // 2, 0), H - side)
    x0 = min(max(cx - side // 2, 0), W - side)
    return y0, y0 + side, x0, x0 + side


def _crop_texels(box: tuple[int, ...], W: int, crop_max: int) -> tuple[np.ndarray, int, int]:
    """Flat grid indices of a box's texels (every k-th when it is larger than ``crop_max``)."""
    y0, y1, x0, x1 = box
    k = max(1, -(-max(y1 - y0, x1 - x0) // crop_max))
    rows = np.arange(y0, y1, k)
    cols = np.arange(x0, x1, k)
    return (rows[:, None] * W + cols[None, :]).reshape(-1), rows.size, cols.size


def normal_picture(n: np.ndarray) -> np.ndarray:
    """A normal map's picture: ``0.5 + 0.5 n`` (the usual tangent-space colours)."""
    return np.clip(0.5 + 0.5 * np.asarray(n, _F), 0.0, 1.0)


def pose_pictures(
    ref: fd.Reference,
    fid: fd.Fidelity,
    base: np.ndarray,
    states: np.ndarray,
    masks: np.ndarray,
    crop_max: int = CROP_MAX,
    base_reader: Reader | None = None,
) -> dict[str, np.ndarray]:
    """Source, shipped and error pictures of every pose (module doc). ``base``, ``states``,
    ``masks``: the shipped maps as decoded (unit normals, combine's representation, 0..1), at
    their own sizes (``base``: or what ``base_reader`` turns into them, texel by texel);
    ``fid``: :func:`wrinklepipe.fidelity.measure` of them with error maps."""
    H, W = ref.shape
    out: dict[str, np.ndarray] = {}
    src_base = ref.base.reshape(-1, 3)
    for pr in ref.poses:
        name = pr.pose.name
        active = pr.active if pr.active is not None else ref.union[pr.sel]
        if active.size == 0:  # the pose touches nothing here (another UDIM tile's pose)
            continue
        box = crop_box(active, ref.shape)
        flat, h, w = _crop_texels(box, W, crop_max)
        # the source: its base, the blended normal where the pose is active
        src = src_base[flat].copy()
        at = np.searchsorted(active, flat)
        hit = (at < active.size) & (active[np.minimum(at, active.size - 1)] == flat)
        src[hit] = np.asarray(pr.normal)[at[hit]]
        # the shipped maps, magnified to the grid as a GPU samples them, blended
        b = model.normalize(fd.sample_at(base, ref.shape, flat, base_reader))
        st = np.stack([fd.sample_at(x, ref.shape, flat) for x in np.asarray(states)])
        if ref.encoding in ("full", "composite"):
            st = model.normalize(st)
        act = model.activations(
            fd.sample_masks_at(masks, ref.shape, flat), pr.pose.weights, ref.policy
        )
        got = model.combine(b, st, act, ref.encoding)
        out[f"fidelity_source/{name}"] = normal_picture(src).reshape(h, w, 3)
        out[f"fidelity_shipped/{name}"] = normal_picture(got).reshape(h, w, 3)
        err = fid.errors.get(name)
        if err is not None:
            out[f"fidelity_error/{name}"] = err.at(flat).reshape(h, w)
    return out


def mask_pictures(
    masks: np.ndarray, region_names: list[str] | tuple[str, ...]
) -> dict[str, np.ndarray]:
    """``region_mask/<region>``: each shipped mask ``[h, w]`` as grey levels in 0..1 (every
    k-th texel when a side is larger than :data:`CROP_MAX`)."""
    m = np.clip(np.asarray(masks, _F), 0.0, 1.0)
    k = max(1, -(-max(m.shape[1], m.shape[2]) // CROP_MAX))
    return {f"region_mask/{r}": m[i, ::k, ::k] for i, r in enumerate(region_names)}
