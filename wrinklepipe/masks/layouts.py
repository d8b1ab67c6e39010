"""Pack region masks into textures and back, under a recorded channel table.

Layouts (the channel table format is documented in docs/regions.md):

``rgba``      four regions per RGBA texture, in region order (Jimenez et al., Oat).
``array``     one texture-array layer per region, any number (Reis et al.).
``lr-split``  the 2009 blog's layout: a left/right pair shares one channel and a split channel (the
              last channel of the last texture) says which side each texel belongs to (1 = the
              character's left), so one channel serves both sides with separate left/right weights.
``jimenez8``  ``rgba`` with at most 8 regions in 2 textures, Jimenez's zones at the paper's
              channels.
``metahuman`` ``rgba`` with MetaHuman's 37 regions in 10 textures (our table), plus an ``array``.

Packing only moves values, so ``unpack(pack(M))`` gives back ``M`` bit for bit, and after 8- or
16-bit quantisation of the textures every mask comes back exactly as its own quantisation
(``lr-split``: the split channel is exactly 0 or 1, so ``c * s`` is exact).
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wrinklepipe.errors import InputError, Problem
from wrinklepipe.model import MAX_REGIONS
from wrinklepipe.presets import jimenez, metahuman

LAYOUTS: tuple[str, ...] = ("rgba", "array", "lr-split", "jimenez8", "metahuman")
CHANNELS = "rgba"

#: How many regions each layout holds.
CAPACITY: dict[str, int] = {
    "rgba": MAX_REGIONS,
    "array": MAX_REGIONS,
    "lr-split": MAX_REGIONS,
    "jimenez8": 8,
    "metahuman": len(metahuman.REGIONS),
}

_SIDE_RE = re.compile(r"^(?P<base>.+?)[_.\-](?P<side>l|r|left|right)$", re.IGNORECASE)


@dataclass
class PackedMasks:
    """Packed masks: ``textures`` ``[T, H, W, 4]`` (``[L, H, W]`` for ``array``) float32 in [0, 1],
    the channel ``table`` (one JSON-able dict per region, in region order), the layout of the
    table (``rgba`` | ``array`` | ``lr-split``), the preset it came from, and for ``metahuman``
    the same masks as a texture array in ``array``."""

    layout: str
    textures: np.ndarray
    table: list[dict[str, Any]]
    preset: str = ""
    array: PackedMasks | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def size(self) -> tuple[int, int]:
        return int(self.textures.shape[1]), int(self.textures.shape[2])


def infer_side(name: str) -> str:
    """The character's side from a name suffix: ``_l``/``_left``/``.L`` -> left, etc."""
    m = _SIDE_RE.match(name)
    if not m:
        return "center"
    return "left" if m.group("side").lower() in ("l", "left") else "right"


def _pair_key(name: str) -> str:
    m = _SIDE_RE.match(name)
    return m.group("base") if m else name


def _check_names(names: Sequence[str], layout: str) -> None:
    problems = []
    seen: set[str] = set()
    for n in names:
        if n in seen:
            problems.append(Problem("<masks>", f"duplicate region name {n!r}"))
        seen.add(n)
    if problems:
        raise InputError(problems)
    cap = CAPACITY[layout]
    if len(names) > cap:
        raise InputError(
            [
                Problem(
                    "<masks>",
                    f"layout {layout!r} holds at most {cap} regions, got {len(names)}; use "
                    "'rgba' or 'array' for more",
                )
            ]
        )


def _rgba_table(names: Sequence[str], slots: Sequence[int]) -> list[dict[str, Any]]:
    return [
        {"region": str(n), "texture": int(s) // 4, "channel": CHANNELS[int(s) % 4]}
        for n, s in zip(names, slots)
    ]


def _slot(entry: dict[str, Any]) -> int:
    return int(entry["texture"]) * 4 + CHANNELS.index(entry["channel"])


def _fill_rgba(masks: np.ndarray, slots: np.ndarray, n_textures: int) -> np.ndarray:
    r, h, w = masks.shape
    out = np.zeros((n_textures, h * w, 4), dtype=np.float32)
    # one strided scatter: region i -> texture slots[i] // 4, channel slots[i] % 4
    out[slots // 4, :, slots % 4] = masks.reshape(r, h * w)
    return out.reshape(n_textures, h, w, 4)


def _preset_slots(names: Sequence[str], preset: dict[str, int], layout: str) -> np.ndarray | None:
    if all(n in preset for n in names):
        return np.array([preset[n] for n in names], dtype=np.int64)
    return None


def pack(
    masks: np.ndarray,
    names: Sequence[str],
    layout: str = "rgba",
    sides: Sequence[str] | None = None,
    lr_conflict: str = "error",
) -> PackedMasks:
    """Pack ``masks`` ``[R, H, W]`` (float in [0, 1]) named ``names`` into ``layout``.

    ``sides`` (``left``/``right``/``center`` per region) is used by ``lr-split``; by default it is
    inferred from the name suffixes (:func:`infer_side`). ``lr_conflict`` says what ``lr-split``
    does with texels that both a left and a right region cover: ``"error"`` (default) refuses,
    ``"dominant"`` gives the texel to the side with the larger value and drops the other side
    there (lossy; the count is in ``PackedMasks.notes``).
    """
    m = np.asarray(masks, dtype=np.float32)
    if m.ndim != 3:
        raise ValueError(f"masks must be [R, H, W], got shape {m.shape}")
    names = [str(n) for n in names]
    if len(names) != m.shape[0]:
        raise InputError(f"{m.shape[0]} masks but {len(names)} names", "<masks>")
    if layout not in LAYOUTS:
        raise InputError(
            f"unknown layout {layout!r}; expected one of {', '.join(LAYOUTS)}", "<masks>"
        )
    _check_names(names, layout)
    r = len(names)
    if layout == "array":
        table = [{"region": n, "layer": i} for i, n in enumerate(names)]
        return PackedMasks("array", np.ascontiguousarray(m.copy()), table, "")
    if layout == "rgba":
        slots = np.arange(r)
        return PackedMasks(
            "rgba", _fill_rgba(m, slots, math.ceil(r / 4)), _rgba_table(names, slots)
        )
    if layout == "jimenez8":
        zone_slot = {z[1]: z[3] * 4 + CHANNELS.index(z[4]) for z in jimenez.ZONES}
        slots = _preset_slots(names, zone_slot, layout)
        if slots is None:
            slots = np.arange(r)
        table = _rgba_table(names, slots)
        return PackedMasks("rgba", _fill_rgba(m, slots, 2), table, "jimenez8")
    if layout == "metahuman":
        mh_slot = {str(e["region"]): _slot(e) for e in metahuman.CHANNEL_TABLE}
        unknown = [n for n in names if n not in mh_slot]
        if unknown:
            raise InputError(
                [
                    Problem(
                        "<masks>",
                        f"region {n!r} is not a MetaHuman region (expected names like "
                        "head_wm1_browsRaiseInner_L; see wrinklepipe.presets.metahuman.REGIONS)",
                    )
                    for n in unknown
                ]
            )
        slots = np.array([mh_slot[n] for n in names], dtype=np.int64)
        packed = PackedMasks(
            "rgba", _fill_rgba(m, slots, metahuman.TEXTURES), _rgba_table(names, slots), "metahuman"
        )
        packed.array = pack(m, names, "array")
        return packed
    return _pack_lr_split(m, names, sides, lr_conflict)


def _pack_lr_split(
    m: np.ndarray, names: list[str], sides: Sequence[str] | None, lr_conflict: str
) -> PackedMasks:
    sides = [infer_side(n) for n in names] if sides is None else [str(s) for s in sides]
    if len(sides) != len(names):
        raise InputError(f"{len(names)} regions but {len(sides)} sides", "<masks>")
    problems: list[Problem] = []
    slot_of_key: dict[tuple[str, str], int] = {}
    members: dict[tuple[int, str], str] = {}
    region_slot: list[int] = []
    n_slots = 0
    for n, side in zip(names, sides):
        if side not in ("left", "right", "center"):
            problems.append(Problem("<masks>", f"region {n!r}: unknown side {side!r}"))
            region_slot.append(-1)
            continue
        key = (_pair_key(n), "sided") if side != "center" else (n, "center")
        if key not in slot_of_key:
            slot_of_key[key] = n_slots
            n_slots += 1
        s = slot_of_key[key]
        if (s, side) in members:
            problems.append(
                Problem("<masks>", f"regions {members[(s, side)]!r} and {n!r} are both {side}")
            )
        members[(s, side)] = n
        region_slot.append(s)
    if problems:
        raise InputError(problems)
    if n_slots + 1 > CAPACITY["lr-split"]:
        raise InputError(
            [
                Problem(
                    "<masks>",
                    f"layout 'lr-split' holds at most {CAPACITY['lr-split'] - 1} shared channels, "
                    f"these regions need {n_slots}",
                )
            ]
        )
    side_arr = np.array(sides)
    is_left = side_arr == "left"
    is_right = side_arr == "right"
    zero = np.zeros(m.shape[1:], np.float32)
    left_max = m[is_left].max(axis=0) if is_left.any() else zero
    right_max = m[is_right].max(axis=0) if is_right.any() else zero
    left_any = left_max > 0
    conflict = left_any & (right_max > 0)
    notes: list[str] = []
    if conflict.any() and lr_conflict == "dominant":
        to_left = left_max >= right_max
        drop = np.where(is_right[:, None, None], conflict & to_left, conflict & ~to_left)
        dropped = np.where(drop, m, 0.0)
        notes.append(
            f"lr-split: {int(conflict.sum())} texels covered by both sides went to the larger "
            f"side; dropped values up to {float(dropped.max()):.4f}"
        )
        m = np.where(drop, np.float32(0.0), m)
        left_any = (m[is_left] > 0).any(axis=0) if is_left.any() else np.zeros_like(left_any)
    elif conflict.any():
        y, x = (int(v) for v in np.argwhere(conflict)[0])
        raise InputError(
            [
                Problem(
                    "<masks>",
                    f"lr-split: {int(conflict.sum())} texels are covered by both a left and a "
                    f"right region (first at texel (x={x}, y={y})); each texel must belong to one "
                    "side. Use 'rgba', fix the masks, or let the larger side win "
                    "(lr_conflict='dominant', --lr-conflict dominant)",
                )
            ]
        )
    n_tex = math.ceil((n_slots + 1) / 4)
    h, w = m.shape[1:]
    # Within a slot at most one member is non-zero at any texel, so the sum is that member:
    # first members are scattered, second members (the other side of a pair) added on top.
    slots = np.array(region_slot, dtype=np.int64)
    first = np.zeros(len(slots), bool)
    first[np.unique(slots, return_index=True)[1]] = True
    textures = _fill_rgba(m[first], slots[first], n_tex)
    if (~first).any():
        textures = textures + _fill_rgba(m[~first], slots[~first], n_tex)
    split_slot = n_tex * 4 - 1
    textures[split_slot // 4, ..., split_slot % 4] = left_any.astype(np.float32)
    split_ref = {"texture": split_slot // 4, "channel": CHANNELS[split_slot % 4]}
    table: list[dict[str, Any]] = []
    for n, side, s in zip(names, sides, region_slot):
        entry: dict[str, Any] = {"region": n, "texture": s // 4, "channel": CHANNELS[s % 4]}
        entry["side"] = side
        if side != "center":
            entry["split"] = dict(split_ref)
        table.append(entry)
    return PackedMasks("lr-split", textures, table, "lr-split", notes=notes)


def check_table(table: Sequence[dict[str, Any]], textures_shape: tuple[int, ...]) -> None:
    """Refuse a channel table that does not fit ``textures_shape`` (names the entry index)."""
    problems: list[Problem] = []
    arr = len(textures_shape) == 3
    n_tex = textures_shape[0]
    names: set[str] = set()

    def ref_ok(ref: Any, i: int, what: str) -> bool:
        if not isinstance(ref, dict):
            problems.append(Problem("<channel table>", f"{what} must be an object", f"/{i}"))
            return False
        t, c = ref.get("texture"), ref.get("channel")
        if not isinstance(t, int) or isinstance(t, bool) or not 0 <= t < n_tex:
            problems.append(
                Problem("<channel table>", f"{what}: texture {t!r} not in 0..{n_tex - 1}", f"/{i}")
            )
            return False
        if c not in tuple(CHANNELS):
            problems.append(
                Problem("<channel table>", f"{what}: channel {c!r} not one of r g b a", f"/{i}")
            )
            return False
        return True

    for i, e in enumerate(table):
        if not isinstance(e, dict) or not isinstance(e.get("region"), str) or not e["region"]:
            problems.append(Problem("<channel table>", "entry needs a 'region' name", f"/{i}"))
            continue
        if e["region"] in names:
            problems.append(
                Problem("<channel table>", f"duplicate region {e['region']!r}", f"/{i}")
            )
        names.add(e["region"])
        if "layer" in e:
            lay = e["layer"]
            if not arr:
                problems.append(
                    Problem("<channel table>", "'layer' needs a texture array", f"/{i}")
                )
            elif not isinstance(lay, int) or isinstance(lay, bool) or not 0 <= lay < n_tex:
                problems.append(
                    Problem("<channel table>", f"layer {lay!r} not in 0..{n_tex - 1}", f"/{i}")
                )
            continue
        if arr:
            problems.append(Problem("<channel table>", "array entries need a 'layer'", f"/{i}"))
            continue
        ref_ok(e, i, f"region {e['region']!r}")
        side = e.get("side", "center")
        if side not in ("left", "right", "center"):
            problems.append(Problem("<channel table>", f"unknown side {side!r}", f"/{i}"))
        elif side != "center":
            if "split" not in e:
                problems.append(
                    Problem("<channel table>", f"{side} region needs a 'split' channel", f"/{i}")
                )
            else:
                ref_ok(e["split"], i, "split")
    if problems:
        raise InputError(problems)


def unpack(
    textures: np.ndarray, table: Sequence[dict[str, Any]]
) -> tuple[tuple[str, ...], np.ndarray]:
    """Invert :func:`pack`: region names (table order) and masks ``[R, H, W]`` float32."""
    tex = np.asarray(textures, dtype=np.float32)
    check_table(table, tex.shape)
    names = tuple(str(e["region"]) for e in table)
    if tex.ndim == 3:
        return names, np.ascontiguousarray(tex[np.array([int(e["layer"]) for e in table], int)])
    n_tex, h, w, _ = tex.shape
    flat = tex.reshape(n_tex, h * w, 4)
    slots = np.array([_slot(e) for e in table], dtype=np.int64)
    out = flat[slots // 4, :, slots % 4]  # one gather -> [R, H*W]
    sided = [i for i, e in enumerate(table) if e.get("side", "center") != "center"]
    if sided:
        split_slots = {_slot(table[i]["split"]) for i in sided}
        split = {s: flat[s // 4, :, s % 4] for s in split_slots}
        for i in sided:  # per region (<= 256), each a vectorised product
            s = split[_slot(table[i]["split"])]
            out[i] *= s if table[i]["side"] == "left" else np.float32(1.0) - s
    return names, out.reshape(len(table), h, w)
