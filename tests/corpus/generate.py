"""Build the golden corpus of validate-asset: one broken asset per rule, made from the demo.

    .venv/bin/python tests/corpus/generate.py          # rewrite every case and its report
    .venv/bin/python tests/corpus/generate.py --check  # fail if a case's codes changed

Each case is a folder ``tests/corpus/<name>/`` with ``asset.wpv`` (a validation bundle: the
shipped textures, channel table, mesh and the source maps) and ``expected.json`` (its report
without volatile fields, see ``wrinklepipe.validate.report.normalized``). ``cases.json`` lists
every case with the codes it was *built* to trigger (written by hand below, not taken from the
validator's output); generating refuses to write a case whose report does not give exactly
those codes. Reports are made with ``tests/corpus/config.toml`` (a small render target).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1]))

from wrinklepipe.asset import WrinkleAsset  # noqa: E402
from wrinklepipe.atomic import dumps_json, write_bytes  # noqa: E402
from wrinklepipe.options import BudgetOptions  # noqa: E402
from wrinklepipe.validate import ValidationInput, load_config, validate  # noqa: E402
from wrinklepipe.validate.loader import bundle_arrays, bundle_bytes, read_bundle  # noqa: E402
from wrinklepipe.validate.report import normalized, report_json  # noqa: E402
from wrinklepipe.validate.ship import ShipOptions, encode_texture, ship_asset  # noqa: E402

SIZE = 128
CONFIG = HERE / "config.toml"


def demo(encoding: str = "pd", policy: str = "clamp01") -> WrinkleAsset:
    """The demo at SIZE with a coarser head mesh (keeps the corpus small)."""
    from dataclasses import replace

    from wrinklepipe.demo import demo_asset

    return replace(
        demo_asset(SIZE, encoding, policy, mesh_resolution=(48, 32)),
        budget=BudgetOptions(max_mean_deg=0.5, max_p99_deg=1.0),
        resolution={},
        provenance={"generator": "tests/corpus/generate.py", "size": SIZE},
    )


def demo_color() -> WrinkleAsset:
    """The corpus demo with colour states (pale where the skin stretches, flushed where it
    compresses)."""
    from wrinklepipe.demo.colors import demo_colors

    a = demo()
    from wrinklepipe.demo import generate

    c = generate(SIZE, mesh_resolution=(48, 32))
    return replace(a, color=demo_colors(c.base_height, c.state_names))


def with_color_state(a: WrinkleAsset, j: int, texels: np.ndarray) -> WrinkleAsset:
    states = a.color.states.copy()
    states[j] = texels
    return replace(a, color=replace(a.color, states=states))


def ship(asset: WrinkleAsset, compress: bool = False) -> ValidationInput:
    inp = ship_asset(asset, ShipOptions(compress=compress))
    inp.path = "asset.wpv"
    inp.pointers = {
        "meta": "asset.wpv#/meta",
        "mesh": "asset.wpv#/mesh",
        "masks": "asset.wpv#/masks",
        "channels": "asset.wpv#/channel_table",
        "expressions": "asset.wpv#/expressions",
        "textures": "asset.wpv#/textures",
        "drivers": "asset.wpv#/drivers",
    }
    for t in inp.textures:
        t.file = f"asset.wpv#/textures/{t.name}"
    return inp


def tex(inp: ValidationInput, name: str) -> object:
    t = inp.texture(name)
    assert t is not None, name
    return t


def u8(t: object) -> np.ndarray:
    return np.frombuffer(t.data, np.uint8).reshape(t.height, t.width, -1).copy()


def set_u8(t: object, arr: np.ndarray) -> None:
    t.data = np.ascontiguousarray(arr, np.uint8).tobytes()


def mesh_of(inp: ValidationInput) -> object:
    return inp.asset.mesh


# ------------------------------------------------------------------------------------------------
# the cases: (name, rule codes it must give, description, builder)


@dataclass
class Case:
    name: str
    expect: list[str]
    description: str
    build: Callable[[], ValidationInput]


def c_clean() -> ValidationInput:
    return ship(demo())


def c_unknown_encoding() -> ValidationInput:
    inp = ship(demo())
    inp.asset = replace(inp.asset, encoding="bump")
    return inp


def c_no_regions() -> ValidationInput:
    a = demo()
    return ship(replace(a, masks=a.masks[:0], regions=(), expressions={}))


def c_missing_state() -> ValidationInput:
    inp = ship(demo())
    inp.textures = [t for t in inp.textures if t.state != "compress"]
    return inp


def c_non_unit() -> ValidationInput:
    inp = ship(demo())
    t = tex(inp, "base_normal")
    a = u8(t).astype(np.float64)
    n = (a[..., :3] / 255.0) * 2 - 1
    n[:, : SIZE // 2] *= 0.8  # a bake that forgot to renormalise
    a[..., :3] = np.rint((n * 0.5 + 0.5) * 255)
    set_u8(t, a)
    return inp


def c_z_negative() -> ValidationInput:
    inp = ship(demo())
    t = tex(inp, "base_normal")
    a = u8(t)
    a[: SIZE // 4, :, 2] = 255 - a[: SIZE // 4, :, 2]  # z mirrored into the surface
    set_u8(t, a)
    return inp


def c_flipped_green() -> ValidationInput:
    inp = ship(demo())
    t = tex(inp, "base_normal")
    a = u8(t)
    a[..., 1] = 255 - a[..., 1]  # DirectX map declared OpenGL
    set_u8(t, a)
    return inp


def c_pd_clipped() -> ValidationInput:
    a = replace(demo(), pd_scale=0.0625)
    return ship(a)


def c_diff_bias() -> ValidationInput:
    inp = ship(demo("diff"))
    for t in inp.by_role("state"):
        a = u8(t).astype(np.int64)
        a[..., :3] += 12
        set_u8(t, np.clip(a, 0, 255))
    return inp


def c_diff_declared_pd() -> ValidationInput:
    inp = ship(demo("diff"))
    inp.asset = replace(inp.asset, encoding="pd")
    return inp


def c_mask_out_of_range() -> ValidationInput:
    a = demo()
    masks = a.masks.copy()
    masks[6] = masks[6] * 1.5  # glabella painted to 1.5 in a float source
    return ship(replace(a, masks=masks))


def c_mask_overlap_additive() -> ValidationInput:
    a = demo(policy="additive")
    masks = a.masks.copy()
    masks[2] = np.maximum(masks[2], masks[6])  # forehead_inner_l also covers the glabella
    return ship(replace(a, masks=masks))


def c_mask_empty() -> ValidationInput:
    a = demo()
    masks = a.masks.copy()
    masks[7] = 0.0  # chin never painted
    return ship(replace(a, masks=masks))


def c_mask_swapped() -> ValidationInput:
    inp = ship(demo())
    t = tex(inp, "mask_1")
    a = u8(t)
    a[..., [0, 2]] = a[..., [2, 0]]  # nose_l <-> glabella
    set_u8(t, a)
    return inp


def c_mask_wrong_side() -> ValidationInput:
    a = demo()
    masks = a.masks.copy()
    masks[4] = masks[4][:, ::-1]  # nose_l painted on the character's right
    return ship(replace(a, masks=masks))


def c_channel_table() -> ValidationInput:
    inp = ship(demo())
    inp.channel_table[3].texture = "mask_9"  # no such texture
    return inp


def c_weight_range() -> ValidationInput:
    a = demo()
    ex = {e: dict(r) for e, r in a.expressions.items()}
    ex["joy"]["forehead_outer_l"] = 1.7
    return ship(replace(a, expressions=ex))


def c_unknown_region() -> ValidationInput:
    a = demo()
    ex = {e: dict(r) for e, r in a.expressions.items()}
    ex["joy"]["cheek_l"] = 0.5
    return ship(replace(a, expressions=ex))


def c_seam_weights() -> ValidationInput:
    inp = ship(demo())
    m = mesh_of(inp)
    w = np.zeros(m.vertex_count, np.float32)
    seam = np.isclose(m.uvs[:, 0], 0.0)  # one side of the back seam only
    w[seam] = 0.5
    inp.vertex_weights = {"dynamic_stretch": w}
    return inp


def c_no_tangents() -> ValidationInput:
    inp = ship(demo())
    inp.asset.mesh = replace(mesh_of(inp), tangents=None)
    return inp


def c_bad_tangents() -> ValidationInput:
    inp = ship(demo())
    m = mesh_of(inp)
    t = m.tangents.copy()
    t[:, 3] *= -1.0  # handedness flipped
    inp.asset.mesh = replace(m, tangents=t)
    return inp


def c_seam_ids() -> ValidationInput:
    inp = ship(demo())
    m = mesh_of(inp)
    ids = m.vertex_ids.copy()
    seam = np.flatnonzero(np.isclose(m.uvs[:, 0], 1.0))
    ids[seam] = ids.max() + 1 + np.arange(len(seam))  # seam twins get fresh IDs
    inp.asset.mesh = replace(m, vertex_ids=ids)
    return inp


def c_dynamic_seam() -> ValidationInput:
    inp = c_seam_ids()  # seam twins with different IDs ...
    m = mesh_of(inp)
    # ... and a morph target (a function of position, so twins move together) that squashes
    # the back of the head more on the character's left: the two sides of the seam differ
    p = m.positions.astype(np.float64)
    phi = np.arctan2(p[:, 0], p[:, 2])
    near = np.clip(1.0 - (np.pi - np.abs(phi)) / 0.8, 0.0, 1.0)
    side = np.clip(0.5 + p[:, 0] / 0.02, 0.0, 1.0)
    delta = np.zeros_like(p)
    delta[:, 1] = -0.2 * near * side * p[:, 1]
    inp.asset.mesh = replace(
        m,
        morph_names=m.morph_names + ("back_squash",),
        morph_deltas=np.concatenate([m.morph_deltas, delta[None].astype(np.float32)]),
    )
    return inp


def c_id_positions() -> ValidationInput:
    inp = ship(demo())
    m = mesh_of(inp)
    ids = m.vertex_ids.copy()
    # two vertices far apart, neither on the UV seam, share one ID
    interior = np.flatnonzero((m.uvs[:, 0] > 0.1) & (m.uvs[:, 0] < 0.9) & (m.uvs[:, 1] > 0.1))
    ids[interior[10]] = ids[interior[-10]]
    inp.asset.mesh = replace(m, vertex_ids=ids)
    return inp


def c_morph_count() -> ValidationInput:
    inp = ship(demo())
    m = mesh_of(inp)
    inp.asset.mesh = replace(m, morph_names=m.morph_names + ("jaw_open",))
    return inp


def c_no_uvs() -> ValidationInput:
    inp = ship(demo())
    inp.asset.mesh = replace(mesh_of(inp), uvs=None)
    return inp


def c_srgb_normal() -> ValidationInput:
    inp = ship(demo())
    tex(inp, "base_normal").srgb = True
    return inp


def c_srgb_mask() -> ValidationInput:
    inp = ship(demo())
    tex(inp, "mask_0").srgb = True
    return inp


def c_bc_size() -> ValidationInput:
    inp = ship(demo(), compress=True)
    t = tex(inp, "base_normal")
    t.width = SIZE - 2  # 126 x 126 stored in 128 x 128 blocks
    t.height = SIZE - 2
    return inp


def c_truncated() -> ValidationInput:
    inp = ship(demo())
    t = tex(inp, "wrinkle_stretch")
    t.data = t.data[: len(t.data) // 2]
    return inp


def c_over_budget() -> ValidationInput:
    return ship(demo(), compress=True)


def c_wasted() -> ValidationInput:
    from wrinklepipe import model
    from wrinklepipe.normals.resample import resize

    a = demo()
    # wrinkles with nothing finer than half the map's size: the wrinkle-only slopes at SIZE / 2,
    # magnified back, over the full base
    d = model.normal_to_pd(a.states) - model.normal_to_pd(a.base)[None]
    smooth = np.stack([resize(resize(x, SIZE // 2), SIZE, "triangle") for x in d])
    states = model.pd_to_normal(model.normal_to_pd(a.base)[None] + smooth)
    return ship(replace(a, states=states, budget=BudgetOptions(max_mean_deg=2.0, max_p99_deg=8.0)))


def c_detail_everywhere() -> ValidationInput:
    """The states carry wrinkle relief over the whole face (as artists often paint them: the
    masks pick where it shows) on top of the base's detail: not misaligned."""
    from wrinklepipe import model

    a = demo()
    h = a.states.shape[1]
    t = (np.arange(h) + 0.5) / h
    relief = np.zeros((h, h, 2), np.float32)
    relief[..., 0] = 0.10 * np.sin(2 * np.pi * 7 * t)[None, :]
    relief[..., 1] = 0.15 * np.cos(2 * np.pi * 9 * t)[:, None]
    states = model.pd_to_normal(model.normal_to_pd(a.states) + relief[None])
    return ship(replace(a, states=states.astype(np.float32)))


def c_other_face() -> ValidationInput:
    """The base of another face (the demo generator's seed 7), the states of this one."""
    from wrinklepipe.demo.character import generate

    a = demo()
    other = generate(SIZE, seed=7, mesh_resolution=(48, 32)).base_normal
    return ship(replace(a, base=np.asarray(other, np.float32)))


def c_base_flipped_v() -> ValidationInput:
    a = demo()
    return ship(replace(a, base=np.ascontiguousarray(a.base[::-1])))  # states keep theirs


def c_side_from_name() -> ValidationInput:
    a = demo()
    regions = tuple(replace(r, side="center") if r.name == "nose_l" else r for r in a.regions)
    return ship(replace(a, regions=regions))


def c_lr_swapped() -> ValidationInput:
    inp = ship(demo())
    t = tex(inp, "mask_0")
    a = u8(t)
    a[..., [0, 1]] = a[..., [1, 0]]
    set_u8(t, a)
    return inp


def c_leak() -> ValidationInput:
    inp = ship(demo())
    a = inp.asset
    t = tex(inp, "mask_1")
    px = u8(t)
    px[..., 2] = np.maximum(px[..., 2], np.rint(a.masks[7] * 255).astype(np.uint8))  # glabella
    set_u8(t, px)  # channel also painted over the chin
    return inp


def c_no_wrinkle() -> ValidationInput:
    inp = ship(demo())
    for t in inp.by_role("state"):
        flat = encode_texture(t.name, "state", np.full((SIZE, SIZE, 2), 0.5, np.float32), "rgba8")
        t.data = flat.data  # wrinkle maps exported empty
    return inp


def c_color_clean() -> ValidationInput:
    return ship(demo_color())


def c_color_aspect() -> ValidationInput:
    inp = ship(demo_color())
    t = next(t for t in inp.by_role("state_color") if t.state == "compress")
    px = np.frombuffer(t.data, np.uint8).reshape(t.height, t.width, -1)
    half = np.ascontiguousarray(px[: t.height // 2])  # 128 x 64: another UV layout
    t.data, t.height = half.tobytes(), half.shape[0]
    return inp


def c_color_flipped() -> ValidationInput:
    a = demo_color()
    return ship(with_color_state(a, 1, a.color.states[1][::-1]))


def c_color_layout() -> ValidationInput:
    a = demo_color()
    rng = np.random.default_rng(3)
    noise = rng.integers(40, 220, a.color.states[0].shape).astype(np.uint8)
    return ship(with_color_state(a, 0, noise))


def c_color_unchanged() -> ValidationInput:
    a = demo_color()
    return ship(with_color_state(a, 0, a.color.base[..., :3]))


def c_color_over_budget() -> ValidationInput:
    inp = ship(demo_color())
    t = next(t for t in inp.by_role("state_color") if t.state == "compress")
    px = np.frombuffer(t.data, np.uint8).reshape(t.height, t.width, -1).astype(np.int64)
    px[..., 1] += 40  # the flush shipped much less red than painted
    t.data = np.clip(px, 0, 255).astype(np.uint8).tobytes()
    return inp


def c_color_linear_tag() -> ValidationInput:
    inp = ship(demo_color())
    for t in inp.by_role("state_color"):
        t.srgb = False  # colour maps uploaded as linear data: the GPU blends the wrong light
    return inp


def _usd_records(layers: dict[str, str]) -> list[dict[str, str]]:
    """The composition records (:mod:`wrinklepipe.usd.composition`) of a real stage made of
    ``layers`` ({file name: usda text}, the first the root), as USD reports them on opening it;
    paths relative to the stage's folder."""
    import json
    import tempfile

    from wrinklepipe.usd.meshes import open_stage_checked

    with tempfile.TemporaryDirectory() as work:
        folder = Path(work).resolve()
        for name, text in layers.items():
            (folder / name).write_text(text)
        _, problems = open_stage_checked(folder / next(iter(layers)))
        text = json.dumps([p.to_json() for p in problems]).replace(f"{folder}/", "")
    return json.loads(text)


def c_usd_missing_layers() -> ValidationInput:
    inp = ship(demo())
    inp.extra["usd_composition"] = _usd_records(
        {
            "hero.usda": "#usda 1.0\n(\n    subLayers = [@./gone.usda@]\n)\n"
            'def Xform "Hat" (references = @./hat.usda@</Hat>) {}\n'
        }
    )
    return inp


def c_usd_cycles() -> ValidationInput:
    inp = ship(demo())
    inp.extra["usd_composition"] = _usd_records(
        {
            "hero.usda": "#usda 1.0\n(\n    subLayers = [@./looks.usda@]\n)\n"
            'def Xform "A" (references = @./b.usda@</B>) {}\n',
            "looks.usda": "#usda 1.0\n(\n    subLayers = [@./hero.usda@]\n)\n",
            "b.usda": '#usda 1.0\ndef Xform "B" (references = @./hero.usda@</A>) {}\n',
        }
    )
    return inp


def _rig(
    drivers: list[dict], curves: dict[str, np.ndarray], records: list[dict], expressions=None
) -> ValidationInput:
    """The demo driven by ``drivers`` whose region-weight curves are ``curves`` (``[T, R]``,
    keyed by frame) and whose records (what they read) are ``records``."""
    a = demo()
    prov = {**a.provenance, "drivers": records}
    ex = a.expressions if expressions is None else expressions
    inp = ship(replace(a, drivers=tuple(drivers), provenance=prov, expressions=ex))
    inp.weight_curves = {k: np.asarray(v, np.float32) for k, v in curves.items()}
    return inp


def _ramp(regions: list[int], r: int = 8) -> np.ndarray:
    """One frame per region of ``regions`` where it is fully on (the others 0)."""
    v = np.zeros((len(regions) + 1, r), np.float32)
    for f, k in enumerate(regions):
        v[f + 1, k] = 1.0
    return v


_DEAD_CLIP = {
    "file": "performance.glb",
    "clip": "Dance",
    "index": 0,
    "clips": ["Dance", "Idle", "Walk"],
    "named": False,
    "inputs": ["browInnerUp", "jawOpen"],
    "moving": [],
    "clips_moving": [],
}
_BLENDSHAPES = {"kind": "blendshapes", "file": "performance.glb"}


def c_dead_rig() -> ValidationInput:
    """A blendshapes driver reading a performance whose clips never move its blend shapes."""
    rec = {"index": 0, "name": "blendshapes", "kind": "blendshapes", "from": "file"}
    rec |= {"clip": _DEAD_CLIP, "inputs": ["browInnerUp", "jawOpen"], "moving": []}
    return _rig([_BLENDSHAPES], {"blendshapes": np.zeros((5, 8))}, [rec], expressions={})


def c_region_never_driven() -> ValidationInput:
    """Keyed curves that drive every region but the chin."""
    return _rig([{"kind": "curves"}], {"curves": _ramp(list(range(7)))}, [], expressions={})


def c_state_never_reached() -> ValidationInput:
    """Every region drives the stretch state only: compress is never reached."""
    a = demo()
    regions = tuple(replace(r, states=("stretch",)) for r in a.regions)
    return ship(replace(a, regions=regions))


def c_clip_implicit() -> ValidationInput:
    """A blendshapes driver that read the second of three clips (the first that moves its
    inputs) because the manifest names none."""
    clip = dict(_DEAD_CLIP, clip="Talk", index=1, clips=["Idle", "Talk", "Walk"])
    clip |= {"moving": ["browInnerUp", "jawOpen"], "clips_moving": ["Talk"]}
    rec = {"index": 0, "name": "blendshapes", "kind": "blendshapes", "from": "file"}
    rec |= {"clip": clip, "inputs": ["browInnerUp", "jawOpen"], "moving": ["browInnerUp"]}
    curves = {"blendshapes": _ramp(list(range(8)))}
    return _rig([_BLENDSHAPES], curves, [rec], expressions={})


def c_table_and_curves() -> ValidationInput:
    """An expression table beside keyed curves that drive every region: the curves win."""
    return _rig([{"kind": "curves"}], {"curves": _ramp(list(range(8)))}, [])


def c_blendshapes_idle() -> ValidationInput:
    """Keyed curves drive every region; a second driver, blendshapes, reads blend shapes
    that stay 0 in its keys."""
    rec = {"index": 1, "name": "blendshapes", "kind": "blendshapes", "from": "keys"}
    rec |= {"inputs": ["browInnerUp", "jawOpen"], "moving": []}
    curves = {"curves": _ramp(list(range(8))), "blendshapes": np.zeros((3, 8))}
    drivers = [{"kind": "curves"}, {"kind": "blendshapes"}]
    return _rig(drivers, curves, [rec], expressions={})


CASES: list[Case] = [
    Case("clean", ["WP-TEX-007"], "the demo, 8-bit, nothing wrong", c_clean),
    Case(
        "load_unknown_encoding",
        ["WP-LOAD-001", "WP-RND-004", "WP-TEX-007"],
        "encoding 'bump' is not a wrinkle encoding",
        c_unknown_encoding,
    ),
    Case(
        "load_no_regions",
        ["WP-LOAD-003", "WP-RND-004", "WP-TEX-007"],
        "no regions: nothing can wrinkle",
        c_no_regions,
    ),
    Case(
        "load_missing_state",
        ["WP-LOAD-002", "WP-RND-004", "WP-TEX-007"],
        "the compress state's texture is missing",
        c_missing_state,
    ),
    Case(
        "map_non_unit",
        ["WP-MAP-001", "WP-TEX-007"],
        "half the base map scaled to length 0.8",
        c_non_unit,
    ),
    Case(
        "map_z_negative",
        ["WP-FID-003", "WP-MAP-002", "WP-TEX-005", "WP-TEX-007"],
        "a quarter of the base map has z < 0",
        c_z_negative,
    ),
    Case(
        "map_flipped_green",
        [
            "WP-FID-001",
            "WP-FID-002",
            "WP-FID-003",
            "WP-FID-004",
            "WP-MAP-003",
            "WP-TEX-005",
            "WP-TEX-007",
        ],
        "base map baked DirectX (green down), declared OpenGL",
        c_flipped_green,
    ),
    Case(
        "map_pd_clipped",
        ["WP-FID-001", "WP-FID-002", "WP-FID-004", "WP-MAP-004", "WP-TEX-005", "WP-TEX-007"],
        "pd maps encoded with scale 1/16: the slopes clip",
        c_pd_clipped,
    ),
    Case(
        "map_diff_bias",
        ["WP-FID-001", "WP-FID-002", "WP-FID-004", "WP-MAP-005", "WP-TEX-005", "WP-TEX-007"],
        "difference maps shifted by 12/255",
        c_diff_bias,
    ),
    Case(
        "map_diff_declared_pd",
        ["WP-FID-001", "WP-FID-002", "WP-FID-004", "WP-MAP-006", "WP-TEX-005", "WP-TEX-007"],
        "difference maps declared as pd",
        c_diff_declared_pd,
    ),
    Case(
        "mask_out_of_range",
        ["WP-FID-002", "WP-MASK-001", "WP-TEX-007"],
        "glabella mask painted up to 1.5 in the source (the shipped 8-bit channel clips)",
        c_mask_out_of_range,
    ),
    Case(
        "mask_overlap_additive",
        ["WP-MASK-002", "WP-TEX-007"],
        "forehead_inner_l overlaps the glabella under policy additive",
        c_mask_overlap_additive,
    ),
    Case("mask_empty", ["WP-MASK-003", "WP-TEX-007"], "the chin mask is empty", c_mask_empty),
    Case(
        "mask_swapped_channels",
        ["WP-FID-001", "WP-FID-002", "WP-MASK-004", "WP-TEX-007"],
        "channels r (nose_l) and b (glabella) of mask_1 swapped",
        c_mask_swapped,
    ),
    Case(
        "mask_wrong_side",
        ["WP-MASK-005", "WP-TEX-007"],
        "nose_l painted on the character's right",
        c_mask_wrong_side,
    ),
    Case(
        "mask_channel_table",
        ["WP-MASK-004", "WP-RND-004", "WP-TEX-007"],
        "a channel-table entry names a texture that does not ship",
        c_channel_table,
    ),
    Case(
        "weight_out_of_range",
        ["WP-WGT-001", "WP-TEX-007"],
        "joy weights forehead_outer_l 1.7 under clamp01",
        c_weight_range,
    ),
    Case(
        "weight_unknown_region",
        ["WP-WGT-002", "WP-TEX-007"],
        "joy weights a region 'cheek_l' that does not exist",
        c_unknown_region,
    ),
    Case(
        "weight_seam_jump",
        ["WP-WGT-003", "WP-TEX-007"],
        "per-vertex dynamic weights differ between UV-seam twins",
        c_seam_weights,
    ),
    Case("mesh_no_tangents", ["WP-MESH-001", "WP-TEX-007"], "no tangents", c_no_tangents),
    Case(
        "mesh_bad_tangents",
        ["WP-MESH-002", "WP-TEX-007"],
        "tangent handedness flipped everywhere",
        c_bad_tangents,
    ),
    Case(
        "mesh_seam_ids",
        ["WP-MESH-003", "WP-TEX-007"],
        "vertex IDs differ across the UV seam",
        c_seam_ids,
    ),
    Case(
        "weight_dynamic_seam",
        ["WP-MESH-003", "WP-TEX-007", "WP-WGT-003"],
        "broken seam IDs make the dynamic weights of a back-of-head morph jump at the seam",
        c_dynamic_seam,
    ),
    Case(
        "mesh_id_positions",
        ["WP-MESH-004", "WP-TEX-007"],
        "two distant vertices share an ID",
        c_id_positions,
    ),
    Case(
        "mesh_morph_count",
        ["WP-MESH-005", "WP-TEX-007"],
        "one more morph-target name than targets",
        c_morph_count,
    ),
    Case(
        "mesh_no_uvs", ["WP-MESH-006", "WP-RND-004", "WP-TEX-007"], "the mesh has no UVs", c_no_uvs
    ),
    Case(
        "tex_srgb_normal",
        ["WP-FID-004", "WP-RND-001", "WP-TEX-001", "WP-TEX-007"],
        "base normal map tagged sRGB",
        c_srgb_normal,
    ),
    Case("tex_srgb_mask", ["WP-TEX-002", "WP-TEX-007"], "mask_0 tagged sRGB", c_srgb_mask),
    Case(
        "tex_bc_size",
        [
            "WP-FID-001",
            "WP-FID-002",
            "WP-FID-003",
            "WP-RND-004",
            "WP-TEX-003",
            "WP-TEX-005",
            "WP-TEX-007",
        ],
        "BC5 base map declared 126 x 126",
        c_bc_size,
    ),
    Case(
        "tex_truncated",
        ["WP-RND-004", "WP-TEX-004", "WP-TEX-007"],
        "wrinkle_stretch holds half its bytes",
        c_truncated,
    ),
    Case(
        "tex_over_budget",
        ["WP-FID-001", "WP-FID-002", "WP-FID-003", "WP-FID-004", "WP-TEX-005", "WP-TEX-007"],
        "BC5/BC7 of the noisy demo base misses a 1 / 4 degree budget",
        c_over_budget,
    ),
    Case(
        "tex_wasted_resolution",
        ["WP-TEX-006", "WP-TEX-007"],
        "a loose budget (2 / 8 degrees) that half-size wrinkle maps still meet",
        c_wasted,
    ),
    Case(
        "fid_detail_everywhere",
        ["WP-TEX-007"],
        "states with wrinkle relief over the whole face and the base's detail: of one face",
        c_detail_everywhere,
    ),
    Case(
        "fid_other_face",
        [
            "WP-FID-001",
            "WP-FID-002",
            "WP-FID-004",
            "WP-FID-007",
            "WP-MAP-004",
            "WP-TEX-005",
            "WP-TEX-007",
        ],
        "the base of another face: the states keep none of its detail",
        c_other_face,
    ),
    Case(
        "map_base_flipped_v",
        [
            "WP-FID-001",
            "WP-FID-002",
            "WP-FID-004",
            "WP-FID-006",
            "WP-MAP-004",
            "WP-TEX-005",
            "WP-TEX-007",
        ],
        "the base map flipped vertically relative to the wrinkle states (said once: not also "
        "as a green flip)",
        c_base_flipped_v,
    ),
    Case(
        "mask_side_from_name",
        ["WP-MASK-006", "WP-TEX-007"],
        "region nose_l declared center: its name says left",
        c_side_from_name,
    ),
    Case(
        "mask_lr_swapped",
        ["WP-MASK-004", "WP-MASK-005", "WP-TEX-007"],
        "channels r (forehead_outer_l) and g (forehead_outer_r) of mask_0 swapped",
        c_lr_swapped,
    ),
    Case(
        "render_leak",
        [
            "WP-FID-001",
            "WP-FID-002",
            "WP-FID-004",
            "WP-MASK-004",
            "WP-RND-002",
            "WP-TEX-005",
            "WP-TEX-007",
        ],
        "the glabella channel is also painted over the chin",
        c_leak,
    ),
    Case(
        "render_no_wrinkle",
        ["WP-FID-001", "WP-FID-002", "WP-FID-004", "WP-RND-003", "WP-TEX-005", "WP-TEX-007"],
        "wrinkle maps exported flat",
        c_no_wrinkle,
    ),
    Case(
        "usd_missing_layers",
        ["WP-TEX-007", "WP-USD-001", "WP-USD-003"],
        "the USD stage's sublayer gone.usda and reference hat.usda do not exist",
        c_usd_missing_layers,
    ),
    Case(
        "usd_cycles",
        ["WP-TEX-007", "WP-USD-002", "WP-USD-004"],
        "the USD stage's sublayers loop (hero -> looks -> hero), and so do its references "
        "(A -> b.usda B -> A)",
        c_usd_cycles,
    ),
    Case(
        "wgt_dead_rig",
        ["WP-TEX-007", "WP-WGT-004"],
        "a blendshapes driver whose clips never move its blend shapes",
        c_dead_rig,
    ),
    Case(
        "wgt_region_never_driven",
        ["WP-TEX-007", "WP-WGT-005"],
        "keyed curves that never drive the chin",
        c_region_never_driven,
    ),
    Case(
        "wgt_state_never_reached",
        ["WP-TEX-007", "WP-WGT-006"],
        "every region drives the stretch state only",
        c_state_never_reached,
    ),
    Case(
        "wgt_clip_implicit",
        ["WP-TEX-007", "WP-WGT-007"],
        "a driver's clip chosen among three: the manifest names none",
        c_clip_implicit,
    ),
    Case(
        "wgt_table_and_curves",
        ["WP-TEX-007", "WP-WGT-008"],
        "an expression table beside driver curves",
        c_table_and_curves,
    ),
    Case(
        "wgt_blendshapes_idle",
        ["WP-TEX-007", "WP-WGT-009"],
        "a blendshapes driver whose keys never move its blend shapes",
        c_blendshapes_idle,
    ),
]


CASES += [
    Case(
        "color_clean", ["WP-TEX-007"], "the demo with colour states, nothing wrong", c_color_clean
    ),
    Case(
        "color_aspect",
        ["WP-COL-001", "WP-FID-008", "WP-TEX-007"],
        "the flushed colour map shipped 128 x 64 (another aspect: another UV layout; half the "
        "face's flush is lost)",
        c_color_aspect,
    ),
    Case(
        "color_flipped",
        ["WP-COL-002", "WP-TEX-007"],
        "the flushed colour map painted upside down",
        c_color_flipped,
    ),
    Case(
        "color_layout",
        ["WP-COL-003", "WP-TEX-007"],
        "the pale colour map is noise: it follows no texel of the base colour",
        c_color_layout,
    ),
    Case(
        "color_unchanged",
        ["WP-COL-004", "WP-TEX-007"],
        "the base colour given as the pale state's colour map",
        c_color_unchanged,
    ),
    Case(
        "color_over_budget",
        ["WP-FID-008", "WP-TEX-007"],
        "the flushed colour map shipped with 40 more green than painted",
        c_color_over_budget,
    ),
    Case(
        "color_linear_tag",
        ["WP-RND-005", "WP-TEX-007"],
        "the colour maps tagged as linear data: the GPU blends encoded values",
        c_color_linear_tag,
    ),
]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--check", action="store_true", help="validate only, write nothing")
    ap.add_argument("cases", nargs="*", help="only these cases")
    args = ap.parse_args(argv)
    config = load_config(CONFIG)
    bad = 0
    index = []
    shared = bundle_arrays(c_clean())  # every case stores only what differs from "clean"
    for case in CASES:
        index.append(
            {"name": case.name, "expect": sorted(case.expect), "description": case.description}
        )
        if args.cases and case.name not in args.cases:
            continue
        inp = case.build()
        if case.name == "clean":
            data = bundle_bytes(inp)
        else:
            data = bundle_bytes(inp, "../clean/asset.wpv", shared)
        folder = HERE / case.name
        if not args.check:
            write_bytes(folder / "asset.wpv", data)
        report = validate(
            read_bundle(folder / "asset.wpv") if not args.check else inp, config=config
        )
        codes = sorted({i.code for i in report.issues})
        ok = codes == sorted(case.expect)
        print(
            f"{'ok ' if ok else 'BAD'} {case.name}: {codes}"
            + ("" if ok else f" (built to give {sorted(case.expect)})")
        )
        bad += not ok
        if ok and not args.check:
            doc = normalized(report_json(report))
            write_bytes(folder / "expected.json", dumps_json(doc).encode())
    if not args.check and not args.cases:
        write_bytes(HERE / "cases.json", dumps_json({"cases": index}).encode())
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
