"""What a wrinkle shader needs to know about one asset, and how region weights reach it.

Every target (the validator's GLSL, three.js, Unreal, Unity, Godot) runs the same core
(:mod:`wrinklepipe.shading.template`). The core sums the masks in *groups* of four (one RGBA mask
texture, four single-channel layers of an ``array`` table, or under ``lr-split`` a texture times
1, the split channel ``s`` or ``1 - s``) and multiplies each group by weight vectors::

    s_q += m.x * W[4 (g Q + q) + 0] + m.y * W[... + 1] + m.z * W[... + 2] + m.w * W[... + 3]

where ``q`` is a quad of four states (``Q`` quads) and lane ``j`` of ``W[i]`` is state ``4 q + j``.
``W`` is a flat array of vec4 the engine fills from the region weights every frame. Where each
region's weight goes is the *slot table*: for region ``r``, the float indices of ``W`` it is
written to (one per state it drives), so an engine's glue is one assignment per slot, whatever
the layout. The channel table, the region -> state matrix and the lr-split sides all live in the
slots; the core never sees them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from wrinklepipe.errors import input_error
from wrinklepipe.metadata import MaskChannel, RegionMeta, WrinkleMeta
from wrinklepipe.model import ENCODINGS, POLICIES

CHANNELS = "rgba"
GATHERS: tuple[str, ...] = ("channels", "layers", "split")

#: The model's scale every target supports (Unity Digital Human: 15 states, 135 regions).
MAX_STATES = 16
#: vec4 weight uniforms a target may use: WebGL2 and D3D11 give at least 1024 fragment uniform
#: vectors on desktop, Unity's ``SetVectorArray`` takes at most 1023 elements.
MAX_WEIGHT_VECTORS = 1023
#: Mask texture layers (a texture array's layers; WebGL2 guarantees 256).
MAX_MASK_LAYERS = 256


@dataclass(frozen=True)
class MaskEntry:
    """Where one region's mask lives: ``layer`` (index into the mask textures), ``channel``
    (0..3) and ``part``: 0 the channel itself, 1 / 2 the left / right half of an lr-split pair
    (``c * s`` / ``c * (1 - s)``)."""

    layer: int
    channel: int
    part: int = 0


@dataclass(frozen=True)
class ShaderSetup:
    """One asset as a shader sees it (every field is plain data; see the module docstring).

    ``region_states`` ``[R][K]`` is 1 where region r drives state k. ``layer_channels`` is the
    channel count of each mask texture. ``base_layout`` / ``state_layout`` are where x, y (and z)
    live in the normal maps (``rgb``, ``rg``: z rebuilt, ``ag``: DXT5nm). ``base_convention`` and
    ``state_convention`` are the green conventions of the maps the shader samples; ``output`` the
    convention of the normal it returns (the engine's).
    """

    encoding: str
    policy: str
    scale: float
    state_names: tuple[str, ...]
    region_names: tuple[str, ...]
    region_states: tuple[tuple[int, ...], ...]
    entries: tuple[MaskEntry, ...]
    layer_names: tuple[str, ...]
    layer_channels: tuple[int, ...]
    split: tuple[int, int] | None = None  # (layer, channel) of the lr-split channel
    base_layout: str = "rgb"
    state_layout: str = "rgb"
    state_bits: int = 8  # bits per stored state channel (8: PNG8 and BCn, 16, 0: float)
    mapping: int = 1  # the value-mapping version of pd / diff states (wrinklepipe.codec)
    base_convention: str = "opengl"
    state_convention: str = "opengl"
    output: str = "opengl"
    #: the states that carry a colour map, in the order of the colour textures (empty: the
    #: shaders are the normal ones, byte for byte)
    color_states: tuple[int, ...] = ()

    # ------------------------------------------------------------------ derived sizes
    @property
    def n_states(self) -> int:
        return len(self.state_names)

    @property
    def n_regions(self) -> int:
        return len(self.region_names)

    @property
    def has_color(self) -> bool:
        """Whether the shaders blend colour (some state carries a colour map)."""
        return bool(self.color_states)

    @property
    def n_layers(self) -> int:
        return len(self.layer_names)

    @property
    def gather(self) -> str:
        """How mask groups are read: ``channels`` (a group is one mask texture), ``layers``
        (four single-channel textures) or ``split`` (a texture times 1, s, 1 - s)."""
        if self.split is not None:
            return "split"
        if self.layer_channels and all(c == 1 for c in self.layer_channels):
            return "layers"
        return "channels"

    @property
    def n_groups(self) -> int:
        g = self.gather
        if g == "layers":
            return (self.n_layers + 3) // 4
        return self.n_layers * (3 if g == "split" else 1)

    @property
    def lanes(self) -> int:
        """Accumulated sums per texel: the states, or one signed sum under ``signed``."""
        return 1 if self.policy == "signed" else self.n_states

    @property
    def quads(self) -> int:
        return (self.lanes + 3) // 4

    @property
    def n_weight_vectors(self) -> int:
        return self.n_groups * self.quads * 4

    def group_channel(self, e: MaskEntry) -> tuple[int, int]:
        """The group and the lane of the group's vec4 a mask entry is read from."""
        g = self.gather
        if g == "layers":
            return e.layer // 4, e.layer % 4
        if g == "split":
            return 3 * e.layer + e.part, e.channel
        return e.layer, e.channel

    # ------------------------------------------------------------------ the slot table
    def slots(self) -> list[list[int]]:
        """Per region, the float indices of the weight array its weight is written to."""
        out = []
        q4 = self.quads
        for r, e in enumerate(self.entries):
            g, c = self.group_channel(e)
            lanes = (
                [0]
                if self.policy == "signed"
                else [k for k in range(self.n_states) if self.region_states[r][k]]
            )
            out.append([((g * q4 + k // 4) * 4 + c) * 4 + k % 4 for k in lanes])
        return out

    def used_vectors(self) -> np.ndarray:
        """``[G, 4]`` 1.0 on the group lanes that hold a region (``renormalize`` sums them)."""
        used = np.zeros((self.n_groups, 4), np.float32)
        for e in self.entries:
            g, c = self.group_channel(e)
            used[g, c] = 1.0
        return used

    def weight_vectors(self, weights: np.ndarray) -> np.ndarray:
        """Region weights -> the flat weight array ``[n_weight_vectors, 4]`` (float32).

        ``weights``: ``[R]`` one weight per region (spread over the states each region drives,
        what the glTF extension animates), or ``[R, K]`` any region x state matrix (the model's
        general form; ``[R]`` or ``[R, 1]`` under ``signed``).
        """
        w = np.asarray(weights, np.float32)
        flat = np.zeros(self.n_weight_vectors * 4, np.float32)
        if w.ndim == 2 and w.shape[1] == 1:
            w = w[:, 0]
        if w.ndim == 1:
            if w.shape[0] != self.n_regions:
                raise ValueError(f"expected {self.n_regions} region weights, got {w.shape[0]}")
            for r, slots in enumerate(self.slots()):
                flat[slots] = w[r]
            return flat.reshape(-1, 4)
        if self.policy == "signed" or w.shape != (self.n_regions, self.n_states):
            raise ValueError(
                f"weights must be [{self.n_regions}] or [{self.n_regions}, {self.n_states}], "
                f"got {list(w.shape)}"
            )
        q4 = self.quads
        for r, e in enumerate(self.entries):
            g, c = self.group_channel(e)
            k = np.arange(self.n_states)
            flat[((g * q4 + k // 4) * 4 + c) * 4 + k % 4] = w[r]
        return flat.reshape(-1, 4)

    def groups_with_weight(self, weights: np.ndarray) -> np.ndarray:
        """``[L]`` bool: mask layers whose groups have a non-zero weight."""
        wv = self.weight_vectors(weights).reshape(self.n_groups, -1)
        on_group = np.abs(wv).max(axis=1) > 0
        g = self.gather
        if g == "layers":
            return np.repeat(on_group, 4)[: self.n_layers]
        if g == "split":
            on = on_group.reshape(self.n_layers, 3).any(axis=1)
            on[self.split[0]] |= bool(on_group.any())  # every weighted group reads s
            return on
        return on_group

    # ------------------------------------------------------------------ limits
    def problems(self) -> list[str]:
        """What this setup asks beyond what every target supports (empty: nothing)."""
        out = []
        if self.encoding not in ENCODINGS:
            out.append(f"unknown encoding {self.encoding!r}")
        if self.policy not in POLICIES:
            out.append(f"unknown policy {self.policy!r}")
        if not self.state_names:
            out.append("no wrinkle states")
        if self.n_states > MAX_STATES:
            out.append(f"{self.n_states} wrinkle states; shaders take at most {MAX_STATES}")
        if self.policy == "signed" and self.n_states != 2:
            out.append(f"policy 'signed' needs exactly two states, the asset has {self.n_states}")
        if any(not 0 <= k < self.n_states for k in self.color_states) or len(
            set(self.color_states)
        ) != len(self.color_states):
            out.append(f"colour states {list(self.color_states)} are not distinct states")
        if not self.region_names:
            out.append("no regions")
        if self.n_layers > MAX_MASK_LAYERS:
            out.append(f"{self.n_layers} mask textures; shaders take at most {MAX_MASK_LAYERS}")
        if self.n_weight_vectors + self.n_groups > MAX_WEIGHT_VECTORS:
            out.append(
                f"{self.n_regions} regions x {self.n_states} states need "
                f"{self.n_weight_vectors + self.n_groups} weight vectors (mask groups "
                f"{self.n_groups} x {self.quads} state quads x 4 + {self.n_groups}); shaders take "
                f"at most {MAX_WEIGHT_VECTORS} (e.g. 135 regions x 16 states in RGBA masks)"
            )
        return out

    def check(self, file: str = "") -> ShaderSetup:
        """Raise one :class:`~wrinklepipe.errors.InputError` listing every problem."""
        problems = self.problems()
        if problems:
            raise input_error(
                file or "<asset>", "cannot build a wrinkle shader: " + "; ".join(problems)
            )
        return self

    def to_json(self) -> dict[str, Any]:
        """The runtime description engines read (``wrinkle_setup.json``'s ``shader`` block)."""
        return {
            "encoding": self.encoding,
            "policy": self.policy,
            "scale": self.scale,
            "stateBits": self.state_bits,
            "mapping": self.mapping,
            "states": list(self.state_names),
            "regions": list(self.region_names),
            "gather": self.gather,
            "maskLayers": self.n_layers,
            "groups": self.n_groups,
            "quads": self.quads,
            "weightVectors": self.n_weight_vectors,
            "slots": self.slots(),
            "used": self.used_vectors().reshape(-1).tolist(),
            "split": list(self.split) if self.split else None,
            "convention": self.base_convention,
            "output": self.output,
            "baseLayout": self.base_layout,
            "stateLayout": self.state_layout,
            **({"colorStates": list(self.color_states)} if self.color_states else {}),
        }


# ------------------------------------------------------------------------------------------------
# construction


def region_state_matrix(
    regions: Sequence[RegionMeta], states: list[str]
) -> tuple[tuple[int, ...], ...]:
    """``[R][K]``: 1 where region r drives state k (a region listing no states drives all)."""
    return tuple(tuple(int(not r.states or s in r.states) for s in states) for r in regions)


def entries_from_table(
    table: Sequence[MaskChannel], n_layers: int
) -> tuple[tuple[MaskEntry, ...], tuple[int, int] | None]:
    """The extension's channel table (texture/layer indices, channel letters) -> entries and the
    lr-split channel. Raises ``ValueError`` on an entry that points nowhere."""
    entries = []
    split: tuple[int, int] | None = None
    for i, e in enumerate(table):
        if e.layer is not None:
            layer, ch, part = e.layer, 0, 0
        else:
            layer, ch = e.index, CHANNELS.index(str(e.channel))
            part = 0
            if e.split is not None:
                sp = (e.split.texture, CHANNELS.index(e.split.channel))
                if split is not None and sp != split:
                    raise ValueError("more than one lr-split channel")
                split = sp
                part = 1 if e.side == "left" else 2 if e.side == "right" else 0
        if not 0 <= layer < n_layers:
            raise ValueError(
                f"channel table entry {i} ({e.region}) names mask {layer} of {n_layers}"
            )
        entries.append(MaskEntry(layer, ch, part))
    return tuple(entries), split


def from_meta(
    meta: WrinkleMeta,
    layer_channels: list[int],
    base_layout: str = "rgb",
    state_layout: str = "rgb",
    state_bits: int = 8,
    convention: str = "opengl",
    output: str | None = None,
) -> ShaderSetup:
    """A setup from the extension's description (a package's ``meta``: names, not indices, for
    textures; the channel table as in ``schemas/WRINKLEPIPE_wrinkle_maps``)."""
    states = meta.state_names
    regions = meta.regions
    layer_names = list(meta.masks.textures)
    entries, split = entries_from_table(meta.masks.table, len(layer_names))
    by_name = {e.region: n for n, e in enumerate(meta.masks.table)}
    order = [by_name[r.name] for r in regions]
    return ShaderSetup(
        encoding=meta.encoding,
        policy=meta.policy,
        scale=float(meta.scale),
        state_names=tuple(states),
        region_names=tuple(meta.region_names),
        region_states=region_state_matrix(regions, states),
        entries=tuple(entries[i] for i in order),
        layer_names=tuple(layer_names),
        layer_channels=tuple(int(c) for c in layer_channels),
        split=split,
        base_layout=base_layout,
        state_layout=state_layout,
        state_bits=int(state_bits),
        mapping=int(meta.mapping),
        base_convention=convention,
        state_convention=convention,
        output=output or convention,
        color_states=tuple(meta.color_states),
    )
