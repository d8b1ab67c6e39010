"""Options and the shared, cached decode of one :class:`ValidationInput` that rules read."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from wrinklepipe import model
from wrinklepipe.asset import WrinkleAsset
from wrinklepipe.fidelity.reference import source_states
from wrinklepipe.fidelity.sampling import Reader
from wrinklepipe.masks import resample_masks
from wrinklepipe.masks.stack import MaskStack, float_masks
from wrinklepipe.normals.held import rows_of
from wrinklepipe.normals.resample import resize_bands
from wrinklepipe.validate import textures as tx
from wrinklepipe.validate.inputs import Texture, ValidationInput
from wrinklepipe.workset import map_rows

#: Bytes of temporaries per texel while decoding a shipped normal map's texels (float32 values
#: of four channels, their squares and the unit vectors).
DECODE_BYTES = 64
#: The render target's side when the options do not set one follows the base map's largest
#: side, within these bounds: at most 512 (the comparison samples the shipped texels at each
#: pixel's UV: a larger target adds pixels, not texels), at least 160 so a small region of a
#: small map still has hundreds of pixels (the avatar's 64^2 maps: its mouth pose's unchanged
#: share for WP-RND-003 is 26-29 % at 160..512, 22 % at 128; the golden corpus renders at 160).
RENDER_SIZE_MIN = 160
RENDER_SIZE_MAX = 512


@dataclass(frozen=True)
class ValidateOptions:
    """What ``validate-asset`` checks and how strictly (defaults are the documented ones).

    ``render``: run the GPU render pass. ``render_size``: square render target in pixels;
    None (the default) follows the maps: the base map's largest side, clamped to
    :data:`RENDER_SIZE_MIN`..:data:`RENDER_SIZE_MAX` (:meth:`Context.render_size`).
    ``gpu_max_mean_deg`` / ``gpu_max_p99_deg``: GPU normal buffer vs numpy reference.
    ``gpu_max_p99_delta_e``: with colour states, the GPU's albedo and lit colour vs the numpy
    colour model of the same shipped bytes (CIEDE2000, p99).
    ``unit_tolerance``: allowed | |n| - 1 | of stored three-channel normals.
    ``max_bad_fraction``: fraction of texels allowed to break a per-texel rule (NaN, z < 0).
    ``max_clipped_fraction``: fraction of pd texels allowed at the edge of the cone.
    ``wrinkle_deg``: a pixel "shows a wrinkle" when it differs from neutral by more than this.
    ``grid``: largest texture-space grid (per side) for source comparisons.
    ``half_res_check``: look for wasted resolution (WP-TEX-006).
    ``dynamic_targets``: morph targets whose dynamic weights are checked across seams (0: off).
    """

    render: bool = True
    render_size: int | None = None
    gpu_max_mean_deg: float = 0.5
    gpu_max_p99_deg: float = 2.0
    gpu_max_p99_delta_e: float = 1.0
    unit_tolerance: float = 0.05
    max_bad_fraction: float = 0.001
    max_clipped_fraction: float = 0.001
    wrinkle_deg: float = 1.0
    leak_fraction: float = 0.002
    grid: int = 512
    half_res_check: bool = True
    dynamic_targets: int = 16  # morph targets whose dynamic weights are checked across seams


def position_groups(positions: np.ndarray) -> np.ndarray:
    """Group index of every vertex: vertices at bit-identical positions share one group."""
    _, inverse = np.unique(np.asarray(positions, np.float32), axis=0, return_inverse=True)
    return inverse.reshape(-1)


def expression_weights(asset: WrinkleAsset, expr: str | None) -> np.ndarray:
    """Weights for one expression at full amount (None: neutral) in the policy's shape.

    Regions the asset does not have are skipped (WP-WGT-002 reports them).
    """
    names = asset.region_names
    per_region = np.zeros(len(names), np.float32)
    if expr is not None:
        for region, w in asset.expressions.get(expr, {}).items():
            if region in names:
                per_region[names.index(region)] += np.float32(w)
    if asset.policy == "signed":
        return per_region
    return per_region[:, None] * asset.region_state_matrix()


#: Bytes of temporaries per source texel while reading a band of normals as PD slopes (float32
#: normals, 1 / z, its clamp, the slopes).
PD_READ_BYTES = 28


def resize_normals(normals: np.ndarray, h: int, w: int) -> np.ndarray:
    """Unit normals ``[H, W, 3]`` resampled in PD space as ``convert`` does
    (:func:`~wrinklepipe.pipeline.package.resize_normals_pd`), bit for bit, made band by band
    of output rows (:func:`resize_rows`): the normals' rows a band's filter reaches are read
    (``normals[rows]``: a band of a held map is decoded there) and made slopes, never the whole
    map's slopes (512 MiB at 8192²) or float32 normals. At their own size: the normals
    themselves (held ones stay held: their rows or texels decoded where read)."""
    if tuple(normals.shape[:2]) == (h, w):
        return rows_of(normals)  # normals held as integers: decoded where read
    return resize_rows(lambda rows: normals[rows], tuple(normals.shape[:2]), h, w)


def resize_rows(
    read: Callable[[slice], np.ndarray], shape: tuple[int, int], h: int, w: int
) -> np.ndarray:
    """:func:`resize_normals` of the ``shape`` = (H, W) map of unit normals whose rows
    ``read(rows)`` gives (``[rows, W, 3]``): its PD slopes resampled band by band of output rows
    (:func:`~wrinklepipe.normals.resample.resize_bands`, each band the rows of the whole
    resample, bit for bit) and turned back into unit normals (per texel)."""
    H, W = int(shape[0]), int(shape[1])

    def slopes(rows: slice) -> np.ndarray:
        return map_rows(model.normal_to_pd, np.asarray(read(rows), np.float32), PD_READ_BYTES)

    out = np.empty((h, w, 3), np.float32)
    for rows, band in resize_bands(slopes, (H, W, 2), (h, w)):
        out[rows] = model.pd_to_normal(band)
    return out


def resize_masks(masks: np.ndarray, h: int, w: int) -> np.ndarray:
    """Masks ``[R, H, W]`` resampled as ``convert`` does (box down, bilinear up), a mask at a
    time (each is resampled on its own: the values of the whole stack's resample, without a
    float32 copy of every mask at full size). Masks with a NaN or an infinity are resampled
    whole, as before: the bilinear zoom spreads them to the neighbouring masks."""
    m = float_masks(masks)
    if not isinstance(m, MaskStack) and not all(np.isfinite(x).all() for x in m):
        return np.asarray(resample_masks(m, (h, w)), np.float32)
    out = np.empty((len(m), h, w), np.float32)
    for r in range(len(m)):
        out[r] = resample_masks(np.asarray(m[r], np.float32)[None], (h, w))[0]
    return out


def encode_source_states(base: np.ndarray, states: np.ndarray, encoding: str) -> np.ndarray:
    """Source (float) states in the representation :func:`wrinklepipe.model.combine` takes
    (:func:`wrinklepipe.fidelity.reference.source_states`, what the automatic choices measure)."""
    return source_states(base, states, encoding)


@dataclass
class Context:
    """Decoded shipped data, shared by all rules (decoded once, lazily)."""

    inp: ValidationInput
    options: ValidateOptions = field(default_factory=ValidateOptions)
    timings: dict[str, float] = field(default_factory=dict)
    metrics: dict[str, object] = field(default_factory=dict)

    _values: dict[str, np.ndarray | None] = field(default_factory=dict)
    _texels: dict[str, np.ndarray | None] = field(default_factory=dict)

    @property
    def asset(self) -> WrinkleAsset:
        return self.inp.asset

    def values(
        self, tex: Texture, apply_srgb: bool = False, keep: bool = True
    ) -> np.ndarray | None:
        """Stored values of a texture in [0, 1] as a sampler returns them (no convention flip:
        that happens after decoding), or None when its bytes cannot be decoded. ``keep``: hold
        them for the next call (``False``: made from the held texels for this call only, for
        a large map read once: 256 MiB of float32 RGBA for a 4096² base)."""
        key = f"{tex.name}|{apply_srgb}"
        if key in self._values:
            return self._values[key]
        q = self.texels(tex)  # (None: undecodable)
        got = None if q is None else tx.decode_values(tex, apply_srgb, q)
        if keep:
            self._values[key] = got
        return got

    def decodable(self, tex: Texture) -> bool:
        """Its texels (and so its values) can be decoded."""
        return self.texels(tex) is not None

    def sample_values(self, tex: Texture, uv: np.ndarray) -> np.ndarray:
        """``tx.bilinear(self.values(tex), uv)`` (the texture's values sampled as the GPU
        does), made from the held texels: each tap's texels are turned into values as
        :func:`wrinklepipe.validate.textures.decode_values` turns every texel (the same float32
        per texel), without the values of the whole map. The texture must be decodable."""
        key = f"{tex.name}|False"
        v = self._values.get(key)
        if v is not None:
            return tx.bilinear(v, uv)
        q = self.texels(tex)
        if q is None:
            raise ValueError(f"{tex.name}: its texels cannot be decoded")
        return tx.bilinear(q, uv, tx.unorm_values)

    def texels(self, tex: Texture) -> np.ndarray | None:
        """Level-0 integer (or float) texels of a texture, or None when undecodable."""
        if tex.name not in self._texels:
            try:
                self._texels[tex.name] = tx.texels(tex)
            except (ValueError, KeyError):
                self._texels[tex.name] = None
        return self._texels[tex.name]

    @staticmethod
    def flips(tex: Texture) -> bool:
        """A normal or wrinkle map declared DirectX: its y is negated after decoding."""
        return tex.convention == "directx" and tex.role in ("base", "state")

    # ---------------------------------------------------------------- shipped, decoded
    @cached_property
    def vertex_groups(self) -> np.ndarray:
        """:func:`position_groups` of the mesh's vertices (the mesh and the weight rules both
        compare seam twins), computed once."""
        mesh = self.asset.mesh
        return position_groups(mesh.positions if mesh is not None else np.zeros((0, 3)))

    @cached_property
    def base_tex(self) -> Texture | None:
        b = self.inp.by_role("base")
        return b[0] if b else None

    @property
    def has_shipped_base(self) -> bool:
        """A base texture whose texels decode (:attr:`shipped_base` is not None)."""
        t = self.base_tex
        return t is not None and self.texels(t) is not None

    @property
    def shipped_base(self) -> np.ndarray | None:
        """Unit normals of the shipped base ``[H, W, 3]`` (None without a usable texture),
        decoded exactly from its texels by the codec. Decoded each time it is asked for, not
        held (192 MiB at 4096², from the map rules to the compression rule before): a rule
        takes it once, for as long as it needs it (its texels are held: 64 MiB)."""
        t = self.base_tex
        if t is None:
            return None
        q = self.texels(t)
        if q is None:
            return None
        # band by band of rows (the codec decodes each texel on its own: the same values),
        # into one C-ordered array (the whole map's decode is not C-ordered: every resample
        # of it copied it first)
        layout, flip = tx.xy_layout(t), self.flips(t)
        return map_rows(
            lambda b: tx.decode_texels(b, "base", layout, 1.0, flip_y=flip), q, DECODE_BYTES
        )

    def shipped_base_texels(self) -> tuple[np.ndarray, Reader] | None:
        """The shipped base as its held texels and the :class:`~wrinklepipe.fidelity.Reader`
        whose ``store`` decodes the texels a sampler reads into :attr:`shipped_base`'s unit
        normals (per texel: the same floats), for the samplers that read a few texels of it
        (the measure's gather at the reference's texels, the pictures' crops): no decoded
        map (192 MiB at 4096²). None without a usable base texture."""
        t = self.base_tex
        q = None if t is None else self.texels(t)
        if t is None or q is None:
            return None
        layout, flip = tx.xy_layout(t), self.flips(t)

        def store(v: np.ndarray) -> np.ndarray:  # [n, C] texels -> [n, 3] unit normals
            return tx.decode_texels(v[None], "base", layout, 1.0, flip_y=flip)[0]

        return q, Reader(store=store)

    def shipped_base_at(self, h: int, w: int, where: np.ndarray) -> np.ndarray | None:
        """``resize_normals(self.shipped_base, h, w)[where]`` (``where``: a boolean ``[h, w]``
        mask): the shipped base at a state's size, as the rules resample it (PD space), at the
        texels ``where`` picks, in row-major order; None without a usable base texture.

        Never whole: at the base's own size the picked texels are decoded (per texel: the same
        floats); else the resample is made band by band of output rows
        (:func:`~wrinklepipe.normals.resample.resize_bands`, which reads the decoded PD slopes
        of the source rows a band's filter taps reach) and each band keeps its picked texels:
        the whole map's values, bit for bit, without its decoded map (768 MiB at 8192²) or its
        resampled copy."""
        t = self.base_tex
        q = None if t is None else self.texels(t)
        if t is None or q is None:
            return None
        layout, flip = tx.xy_layout(t), self.flips(t)

        def decode(v: np.ndarray) -> np.ndarray:  # stored texels -> unit normals, per texel
            return tx.decode_texels(v, "base", layout, 1.0, flip_y=flip)

        pick = np.asarray(where, bool)
        if q.shape[:2] == (h, w):
            return np.asarray(decode(q[pick][None])[0], np.float32)
        H, W = q.shape[:2]

        def read(rows: slice) -> np.ndarray:  # the PD slopes of decoded source rows
            return map_rows(
                lambda b: model.normal_to_pd(np.asarray(decode(b), np.float32)),
                q[rows],
                DECODE_BYTES,
            )

        out = [
            np.asarray(model.pd_to_normal(band), np.float32)[pick[rows]]
            for rows, band in resize_bands(read, (H, W, 2), (h, w))
        ]
        return np.concatenate(out) if out else np.zeros((0, 3), np.float32)

    @cached_property
    def shipped_states(self) -> list[np.ndarray] | None:
        """Each state in combine's representation (None if any is missing or undecodable),
        decoded exactly from its texels by the codec under the texture's mapping version."""
        a = self.asset
        if a.encoding not in model.ENCODINGS:
            return None
        out = []
        for t in self.inp.state_textures():
            if t is None:
                return None
            q = self.texels(t)
            if q is None:
                return None
            try:
                out.append(
                    tx.decode_texels(
                        q, a.encoding, tx.xy_layout(t), a.pd_scale, t.mapping, self.flips(t)
                    )
                )
            except ValueError:
                return None
        return out

    @cached_property
    def shipped_masks(self) -> np.ndarray | None:
        """Region masks ``[R, H, W]`` read through the channel table (None if it is unusable)."""
        inp = self.inp
        if not inp.channel_table:
            return None
        by_region = {e.region: e for e in inp.channel_table}
        layers = []
        shape = None
        for r in self.asset.region_names:
            e = by_region.get(r)
            t = inp.texture(e.texture) if e else None
            if e is None or t is None or e.channel >= t.channels:
                return None
            v = self.values(t)
            if v is None:
                return None
            if shape is not None and v.shape[:2] != shape:
                return None
            shape = v.shape[:2]
            m = v[..., e.channel]
            if e.split is not None:
                st = inp.texture(e.split[0])
                sv = self.values(st) if st is not None else None
                if sv is None or e.split[1] >= sv.shape[-1] or sv.shape[:2] != shape:
                    return None
                s = sv[..., e.split[1]]
                m = m * s if e.side == "left" else m * (1.0 - s) if e.side == "right" else m
            layers.append(m)
        if not layers:
            return None
        return np.stack(layers).astype(np.float32)

    @cached_property
    def render_size(self) -> int:
        """The render pass's square target: ``options.render_size`` when set, else the base
        map's largest side clamped to RENDER_SIZE_MIN..RENDER_SIZE_MAX (RENDER_SIZE_MAX
        without a base texture)."""
        if self.options.render_size:
            return int(self.options.render_size)
        t = self.base_tex
        if t is None:
            return RENDER_SIZE_MAX
        return min(max(int(t.width), int(t.height), RENDER_SIZE_MIN), RENDER_SIZE_MAX)

    # ---------------------------------------------------------------- comparison grid
    @cached_property
    def grid_shape(self) -> tuple[int, int]:
        """Texture-space grid for shipped-vs-source comparisons (the largest shipped normal
        map, capped at ``options.grid``)."""
        sizes = [t.height for t in self.inp.textures if t.role in ("base", "state")]
        if not sizes:
            sizes = [int(self.asset.base.shape[0])]
        n = min(max(sizes), self.options.grid)
        return n, n

    def to_grid(self, img: np.ndarray) -> np.ndarray:
        h, w = self.grid_shape
        if img.ndim == 2:
            return tx.resize_bilinear(img[..., None], h, w)[..., 0]
        return tx.resize_bilinear(img, h, w)

    def masks_to_grid(self, masks: np.ndarray) -> np.ndarray:
        h, w = self.grid_shape
        return np.moveaxis(tx.resize_bilinear(np.moveaxis(masks, 0, -1), h, w), -1, 0)

    @cached_property
    def source_at_shipped_size(self) -> dict[str, np.ndarray] | None:
        """The source resampled to the shipped sizes the way ``convert`` resamples (normals in
        PD space, masks box-down / bilinear-up), so comparisons measure what encoding,
        quantisation and compression lost, not the chosen resolution (WP-TEX-006 covers that).

        Keys: ``states`` and ``base_at_states`` (at the state textures' size), ``masks`` (at
        the mask textures' size). The base at the base texture's size is not held
        (:attr:`source_on_grid` reads it where the grid's taps fall).
        """
        a = self.asset
        if not self.inp.has_source or len(a.states) == 0:
            return None
        sts = [t for t in self.inp.state_textures() if t is not None]
        hs, ws = (sts[0].height, sts[0].width) if sts else a.states.shape[1:3]
        out = {
            "states": self._source_states_at(hs, ws),
            "base_at_states": resize_normals(a.base, hs, ws),
        }
        masks = a.masks
        ship = self.shipped_masks
        if ship is not None and masks.shape[0] and ship.shape[1:] != masks.shape[1:]:
            out["masks"] = resize_masks(masks, *ship.shape[1:])
        else:
            out["masks"] = np.asarray(masks, np.float32)
        return out

    def _source_states_at(self, h: int, w: int) -> np.ndarray:
        """The source states ``[K, h, w, 3]`` each resampled as :func:`resize_normals` does,
        into one array, a state's band of rows read at a time (``states[k, rows]``)."""
        states = self.asset.states
        K, H, W = (int(x) for x in states.shape[:3])
        if (H, W) == (h, w):
            return np.stack([np.asarray(states[k], np.float32) for k in range(K)])
        out = np.empty((K, h, w, 3), np.float32)
        for k in range(K):
            out[k] = resize_rows(lambda rows, k=k: states[k, rows], (H, W), h, w)
        return out

    @cached_property
    def source_on_grid(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Source base, encoded states and masks on the grid (needs ``has_source``)."""
        a = self.asset
        src = self.source_at_shipped_size
        if src is None or a.encoding not in model.ENCODINGS:
            return None
        enc = encode_source_states(src["base_at_states"], src["states"], a.encoding)
        st = []
        for s in enc:
            g = self.to_grid(s)
            if a.encoding in ("full", "composite"):
                g = model.normalize(g)
            st.append(g)
        base = model.normalize(self._source_base_on_grid())
        return base, np.stack(st).astype(np.float32), self.masks_to_grid(src["masks"])

    def _source_base_on_grid(self) -> np.ndarray:
        """``to_grid(resize_normals(asset.base, *base texture's size))``: the source base at the
        shipped base's size on the grid. At the source's own size the grid's taps read the
        source base's texels (``base[rows, cols]``: a held map decodes those), never the
        whole map as float32 (768 MiB at 8192²); the same floats (the taps' texels are the
        map's, the same sums)."""
        a = self.asset
        base = a.base
        H, W = (int(x) for x in base.shape[:2])
        bt = self.base_tex
        hb, wb = (bt.height, bt.width) if bt is not None else (H, W)
        h, w = self.grid_shape
        if (hb, wb) != (H, W):
            return self.to_grid(resize_normals(base, hb, wb))
        if (h, w) == (H, W):
            return np.asarray(base, np.float32)

        def gather(flat: np.ndarray) -> np.ndarray:  # [n] -> the texels' [n, 3] normals
            return np.asarray(base[flat // W, flat % W], np.float32)

        return tx.resize_bilinear_at(gather, (H, W), h, w)

    @cached_property
    def shipped_on_grid(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Shipped base, states (combine representation) and masks on the grid."""
        shipped = self.shipped_base_texels()
        if shipped is None or self.shipped_states is None:
            return None
        masks = self.shipped_masks if self.shipped_masks is not None else self.asset.masks
        # the base's texels the grid's taps read, decoded there (no decoded map of the base)
        h, w = self.grid_shape
        base = model.normalize(tx.resize_bilinear(shipped[0], h, w, shipped[1].store))
        st = []
        for s in self.shipped_states:
            g = self.to_grid(s)
            if self.asset.encoding in ("full", "composite"):
                g = model.normalize(g)
            st.append(g)
        return base, np.stack(st).astype(np.float32), self.masks_to_grid(masks)

    def expressions(self) -> list[str | None]:
        """Neutral (None) and every expression, in a stable order."""
        return [None, *sorted(self.asset.expressions)]

    def weights(self, expr: str | None) -> np.ndarray:
        return expression_weights(self.asset, expr)
