"""Read grayscale region masks from any format the image reader takes (PNG, TIFF, EXR, ...).

A mask is ``[H, W]`` float32 in [0, 1]: 0 = no wrinkle, 1 = full wrinkle. Reis et al. paint the
other way round (white = no wrinkle, black = full); ``invert=True`` converts (``1 - v``).
An RGB(A) mask is accepted only if its colour channels are equal (alpha is ignored); float files
must hold finite values in [0, 1].
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wrinklepipe.errors import InputError, Problem
from wrinklepipe.io.images import DEFAULT_MAX_PIXELS, ImageInfo, read_image
from wrinklepipe.masks.stack import CroppedMasks, MaskStack, quantized, to_float

#: Largest difference between the R, G and B channels of a "grey" mask (below one 16-bit step).
GREY_TOLERANCE = 0.5 / 65535.0


@dataclass
class MaskSet:
    """Masks read from files: names, ``masks`` ``[R, H, W]`` float32, source files, bits."""

    names: tuple[str, ...]
    masks: np.ndarray
    files: tuple[str, ...]
    bits: int  # 8 or 16: the deepest integer storage among the inputs (16 for float files)


def _bits_of(info: ImageInfo) -> int:
    return 8 if info.format == "uint8" else 16


def _count(n: int) -> str:
    return f"{n} texel" if n == 1 else f"{n} texels"


def _texel(flat_index: int, width: int) -> str:
    y, x = divmod(int(flat_index), width)
    return f"texel (x={x}, y={y})"


def mask_from_pixels(pixels: np.ndarray, file: str | Path, invert: bool = False) -> np.ndarray:
    """Check decoded pixels ``[H, W, C]`` and reduce them to one grey channel ``[H, W]``."""
    px = np.asarray(pixels, dtype=np.float32)
    if px.ndim == 2:
        px = px[..., None]
    h, w, c = px.shape
    colour = px[..., : min(c, 3)] if c != 2 else px[..., :1]
    grey = colour[..., 0]
    bad = ~np.isfinite(grey)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise InputError([Problem(str(file), f"{_texel(i, w)} is not a finite number")])
    if colour.shape[-1] == 3:
        spread = colour.max(axis=-1) - colour.min(axis=-1)
        if float(spread.max()) > GREY_TOLERANCE:
            i = int(np.argmax(spread))
            n = int((spread > GREY_TOLERANCE).sum())
            r, g, b = (float(v) for v in colour.reshape(-1, 3)[i])
            raise InputError(
                [
                    Problem(
                        str(file),
                        f"RGB mask whose channels differ at {_count(n)} (first at {_texel(i, w)}: "
                        f"R={r:.4f} G={g:.4f} B={b:.4f}); a mask must be grey. Save it as "
                        "grayscale or split the channels into separate masks",
                    )
                ]
            )
    lo, hi = float(grey.min()), float(grey.max())
    if lo < 0.0 or hi > 1.0:
        out = (grey < 0.0) | (grey > 1.0)
        i = int(np.argmin(grey)) if lo < 0.0 else int(np.argmax(grey))
        what = "negative values" if lo < 0.0 else "values above 1"
        raise InputError(
            [
                Problem(
                    str(file),
                    f"mask has {what}: {_count(int(out.sum()))} outside [0, 1] (range {lo:.6g} .. "
                    f"{hi:.6g}, worst at {_texel(i, w)}); masks must lie in [0, 1]",
                )
            ]
        )
    m = np.ascontiguousarray(grey, dtype=np.float32)
    if invert:
        m = (np.float32(1.0) - m).astype(np.float32)
    return m


def read_mask(
    path: str | Path, invert: bool = False, max_pixels: int = DEFAULT_MAX_PIXELS
) -> tuple[np.ndarray, ImageInfo]:
    """Read one mask file as ``[H, W]`` float32 in [0, 1] (``invert``: Reis's white = none)."""
    pixels, info = read_image(path, max_pixels)
    return mask_from_pixels(pixels, path, invert), info


def stack_masks(
    arrays: Sequence[np.ndarray],
    names: Sequence[str],
    files: Sequence[str | Path] | None = None,
) -> np.ndarray:
    """Stack ``[H, W]`` masks into ``[R, H, W]``; refuse different sizes and duplicate names."""
    check_masks([np.shape(a) for a in arrays], names, files)
    return np.ascontiguousarray(np.stack([np.asarray(a, np.float32) for a in arrays]))


def check_masks(
    shapes: Sequence[tuple[int, ...]],
    names: Sequence[str],
    files: Sequence[str | Path] | None = None,
) -> None:
    """Refuse masks of different ``shapes`` and duplicate or empty ``names`` (one problem each)."""
    files = [str(f) for f in files] if files is not None else [f"<{n}>" for n in names]
    if len(shapes) != len(names):
        raise InputError(f"{len(shapes)} masks but {len(names)} names", "<masks>")
    if not shapes:
        raise InputError("no masks given", "<masks>")
    problems: list[Problem] = []
    seen: dict[str, str] = {}
    for name, f in zip(names, files):
        if not name:
            problems.append(Problem(f, "empty region name"))
        elif name in seen:
            problems.append(
                Problem(f, f"duplicate region name {name!r} (also used by {seen[name]})")
            )
        else:
            seen[name] = f
    shapes = [tuple(a) for a in shapes]
    if len(set(shapes)) > 1:
        first = shapes[0]
        for s, f in zip(shapes, files):
            if s != first:
                problems.append(
                    Problem(
                        f,
                        f"masks of different sizes: this one is {s[1]} x {s[0]}, {files[0]} is "
                        f"{first[1]} x {first[0]}; all masks must share one size",
                    )
                )
    if problems:
        raise InputError(problems)


def read_masks(
    paths: Sequence[str | Path],
    names: Sequence[str] | None = None,
    invert: bool = False,
    max_pixels: int = DEFAULT_MAX_PIXELS,
    integers: bool = False,
) -> MaskSet:
    """Read several mask files (region names default to the file stems) into a :class:`MaskSet`.

    ``integers``: hold the stack in its files' integers (a :class:`~wrinklepipe.masks.stack.
    MaskStack`, 1 or 2 bytes a texel instead of 4) when every mask's float values are its
    integers' exactly (8- or 16-bit files, not inverted); else, as without it, float32."""
    paths = [Path(p) for p in paths]
    if names is None:
        names = [p.stem for p in paths]
    if len(names) != len(paths):
        raise InputError(f"{len(paths)} mask files but {len(names)} names", "<masks>")
    # each mask goes into its place in the stack as it is read: one full-size mask beside the
    # stack, not a list of them and a stacked copy
    stacked: np.ndarray | None = None
    shapes: list[tuple[int, ...]] = []
    bits = 8
    problems: list[Problem] = []
    for i, p in enumerate(paths):
        try:
            m, info = read_mask(p, invert, max_pixels)
        except InputError as exc:
            problems.extend(exc.problems)
            continue
        shapes.append(m.shape)
        if stacked is None:
            whole = integers and info.format in ("uint8", "uint16")
            dtype = np.dtype(info.format) if whole else np.dtype(np.float32)
            stacked = np.empty((len(paths), *m.shape), dtype)
        if m.shape == stacked.shape[1:]:
            if stacked.dtype != np.float32:
                q = quantized(m, 8 * stacked.dtype.itemsize)
                if q is None:  # not its integers: the stack (exact so far) as float32
                    stacked = to_float(stacked)
                else:
                    m = q
            stacked[i] = m
        del m
        bits = max(bits, _bits_of(info))
    if problems:
        raise InputError(problems)
    check_masks(shapes, list(names), paths)
    assert stacked is not None  # check_masks refuses no masks
    held: np.ndarray | MaskStack = stacked
    if stacked.dtype != np.float32:  # integers; boxed where most of each mask is zero
        held = CroppedMasks(stacked) if CroppedMasks.saves(stacked) else MaskStack(stacked)
    del stacked
    return MaskSet(tuple(names), held, tuple(str(p) for p in paths), bits)  # type: ignore[arg-type]
