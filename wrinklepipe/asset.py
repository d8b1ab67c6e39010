"""The in-memory asset: plain dataclasses of numpy arrays that every stage reads and returns.

Conventions (DESIGN.md section 4): float32 unit normals with OpenGL green (+Y), UV origin at the
top-left (glTF), masks in [0, 1] channels-first ``[R, H, W]``. Conversions happen at ingest and
export only, and are recorded in ``provenance``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wrinklepipe.codec import srgb
from wrinklepipe.options import BudgetOptions

#: The largest mesh the readers accept, checked on the counts a file declares before the
#: arrays are built (every corner costs ~140 bytes through triangulation, welding, tangents and
#: vertex IDs): 2^24 points and 2^25 face corners (about 11 million triangles, ~4.5 GB).
MAX_MESH_POINTS = 1 << 24
MAX_MESH_CORNERS = 1 << 25


def mesh_over_cap(points: int, corners: int) -> str:
    """What is over the mesh caps, in words ("" when nothing is)."""
    if corners > MAX_MESH_CORNERS:
        return (
            f"declares {corners} face corners, over the cap of {MAX_MESH_CORNERS} (about "
            f"{MAX_MESH_CORNERS // 3 // 1_000_000} million triangles); decimate the mesh"
        )
    if points > MAX_MESH_POINTS:
        return f"declares {points} points, over the cap of {MAX_MESH_POINTS}; decimate the mesh"
    return ""


@dataclass(frozen=True)
class MeshPart:
    """Where a run of a merged mesh's vertices comes from: vertices ``start .. start + count``
    are, in order, the vertices of the source primitive at ``pointer`` (a glTF JSON pointer
    such as ``/meshes/2/primitives/0``, or a USD ``Mesh`` prim path) instanced by node ``node``.

    A USD part also says how its render vertices map back onto the prim's topology:
    ``corners[c]`` is the render vertex (``0 .. count``) of ``faceVertexIndices[c]``, and
    ``transform`` the 4x4 (column vectors) the reader applied to the prim's points (its
    local-to-world, or the skin's ``geomBindTransform``)."""

    name: str
    pointer: str
    start: int
    count: int
    node: int | None = None
    corners: np.ndarray | None = None  # [C] int64, USD: faceVertexIndices corner -> vertex
    transform: np.ndarray | None = None  # [4, 4] float64, USD: prim space -> these vertices


@dataclass
class Mesh:
    """A triangulated render mesh (vertices split where UVs or normals are discontinuous)."""

    positions: np.ndarray  # [V, 3] float32
    indices: np.ndarray  # [T, 3] uint32
    uvs: np.ndarray | None = None  # [V, 2] float32, glTF convention (v = 0 at the top)
    normals: np.ndarray | None = None  # [V, 3] float32
    tangents: np.ndarray | None = None  # [V, 4] float32, w = handedness +-1 (MikkTSpace)
    morph_names: tuple[str, ...] = ()
    morph_deltas: np.ndarray | None = None  # [M, V, 3] float32 position deltas
    joints: np.ndarray | None = None  # [V, 4] int joint indices into ``joint_names``
    skin_weights: np.ndarray | None = None  # [V, 4] float32
    joint_names: tuple[str, ...] = ()
    inverse_bind: np.ndarray | None = None  # [J, 4, 4] float32
    vertex_ids: np.ndarray | None = None  # [V] int64 spatial-hash IDs (Oat)
    colors: np.ndarray | None = None  # [V, 4] float32 (rest-pose wrinkle bias lives here)
    name: str = "mesh"
    notes: list[str] = field(default_factory=list)  # what ingest did (triangulated, xatlas UVs...)
    #: The source primitives the vertices come from (a glTF document's wrinkled primitives).
    parts: tuple[MeshPart, ...] = ()

    @property
    def vertex_count(self) -> int:
        return int(self.positions.shape[0])

    @property
    def triangle_count(self) -> int:
        return int(self.indices.shape[0])


@dataclass
class Region:
    """A facial region: a mask and the states it drives."""

    name: str
    side: str = "center"  # "left" | "right" | "center" (the character's sides)
    states: tuple[str, ...] = ()  # state names this region activates (empty: all)


@dataclass
class ColorMaps:
    """The colour half of the appearance states: sRGB texels as stored, and which states carry
    one (the model blends them in linear light: :func:`wrinklepipe.model.combine_color`).

    ``base`` is the base colour's texels ``[H, W, C]`` (uint8 / uint16, C = 3 or 4: an alpha
    channel passes through untouched), ``states`` the colour maps ``[Kc, Hs, Ws, 3]`` of the
    states ``state_index`` (indices into the asset's ``state_names``), ``factor`` the linear
    multiplier of the base colour (a glTF material's ``baseColorFactor``), ``from_material``
    whether the base is the wrinkled material's own ``baseColorTexture`` (it then ships as it
    is). States are at the base's size as read; the automatic size choice may make them smaller.
    """

    base: np.ndarray
    states: np.ndarray
    state_index: tuple[int, ...]
    factor: tuple[float, float, float] = (1.0, 1.0, 1.0)
    from_material: bool = False

    @property
    def bits(self) -> int:
        return 16 if self.base.dtype == np.uint16 else 8

    def base_linear(self) -> np.ndarray:
        """``C_B``: the base colour in linear light, ``factor`` applied (``[H, W, 3]``)."""
        lin = srgb.decode_texels(self.base[..., :3])
        if self.factor != (1.0, 1.0, 1.0):
            lin = (lin * np.asarray(self.factor, np.float32)).astype(np.float32)
        return lin

    def states_linear(self) -> np.ndarray:
        """``C_k``: the states' colours in linear light (``[Kc, Hs, Ws, 3]``)."""
        return srgb.decode_texels(self.states[..., :3])


@dataclass
class WrinkleAsset:
    """Everything one character's wrinkle setup holds.

    ``states`` are the normal maps of the face in each wrinkled pose, *including* the base
    detail (what an artist sculpts), as unit normals; the encodings derive what they store
    from these and ``base`` (:mod:`wrinklepipe.model`).
    """

    name: str
    base: np.ndarray  # [H, W, 3] float32 unit normals
    states: np.ndarray  # [K, Hs, Ws, 3] float32 unit normals (wrinkled face)
    state_names: tuple[str, ...]
    masks: np.ndarray  # [R, Hm, Wm] float32 in [0, 1]
    regions: tuple[Region, ...]
    expressions: dict[str, dict[str, float]] = field(default_factory=dict)
    encoding: str = "pd"
    policy: str = "clamp01"
    pd_scale: float = 1.0
    mesh: Mesh | None = None
    drivers: list[dict[str, Any]] = field(default_factory=list)
    budget: BudgetOptions = field(default_factory=BudgetOptions)
    resolution: dict[str, int] = field(default_factory=dict)
    provenance: dict[str, Any] = field(default_factory=dict)
    #: the states' colour maps and the base colour (None: no state carries a colour)
    color: ColorMaps | None = None
    #: the states that carry no normal map (a colour-only state: its normal is the base)
    color_only: tuple[int, ...] = ()

    @property
    def region_names(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.regions)

    def region_state_matrix(self) -> np.ndarray:
        """``[R, K]`` 1.0 where region r drives state k (a region with no states drives all)."""
        out = np.zeros((len(self.regions), len(self.state_names)), dtype=np.float32)
        for i, r in enumerate(self.regions):
            for k, s in enumerate(self.state_names):
                if not r.states or s in r.states:
                    out[i, k] = 1.0
        return out

    def expression_weights(self, expression_weights: dict[str, float]) -> np.ndarray:
        """Region x state weights ``[R, K]`` for a mix of expressions (before the policy)."""
        per_region = np.zeros(len(self.regions), dtype=np.float32)
        names = self.region_names
        for expr, amount in expression_weights.items():
            row = self.expressions[expr]
            for region, w in row.items():
                per_region[names.index(region)] += np.float32(amount * w)
        return per_region[:, None] * self.region_state_matrix()
