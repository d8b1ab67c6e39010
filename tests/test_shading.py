"""The shader template's setup: the slot table puts every region weight where the core reads it,
the render pass runs at Unity Digital Human scale, and a larger asset is refused clearly.

The group sums are checked against ``wrinklepipe.model.region_sum`` on masks unpacked by
``wrinklepipe.masks.unpack`` (an independent reader of the channel table).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wrinklepipe import masks as wm
from wrinklepipe import model
from wrinklepipe.asset import Region
from wrinklepipe.demo import demo_asset
from wrinklepipe.errors import InputError
from wrinklepipe.metadata import WrinkleMeta
from wrinklepipe.shading import template as tpl
from wrinklepipe.shading.setup import MAX_WEIGHT_VECTORS, from_meta


def _meta(layout: str, n_regions: int, n_states: int, policy: str, drives: np.ndarray):
    names = [
        f"reg{i}_{'l' if i % 3 == 0 else 'r' if i % 3 == 1 else 'c'}" for i in range(n_regions)
    ]
    sides = [wm.infer_side(n) for n in names]
    states = [f"s{k}" for k in range(n_states)]
    regions = [
        {"name": n, "side": s, "states": [states[k] for k in range(n_states) if drives[i, k]]}
        for i, (n, s) in enumerate(zip(names, sides, strict=True))
    ]
    return names, sides, states, regions


def _group_masks(setup, textures: np.ndarray) -> np.ndarray:
    """What the core reads per mask group (``[G, N, 4]``) from mask textures ``[L, N, 4]``."""
    g = setup.gather
    if g == "channels":
        return textures
    if g == "layers":
        pad = np.zeros((setup.n_groups * 4, textures.shape[1]), np.float32)
        pad[: setup.n_layers] = textures[..., 0]
        return np.moveaxis(pad.reshape(setup.n_groups, 4, -1), 1, 2)
    layer, ch = setup.split
    s = textures[layer, :, ch][None, :, None]
    return np.stack([textures, textures * s, textures * (1 - s)], axis=1).reshape(
        -1, textures.shape[1], 4
    )


@settings(max_examples=40, deadline=None)
@given(
    layout=st.sampled_from(["rgba", "array", "lr-split"]),
    n_regions=st.integers(1, 23),
    n_states=st.integers(1, 16),
    policy=st.sampled_from(["clamp01", "signed", "additive"]),
    seed=st.integers(0, 2**31),
)
def test_slot_table_puts_each_weight_where_the_core_reads_it(
    layout, n_regions, n_states, policy, seed
):
    rng = np.random.default_rng(seed)
    if policy == "signed":
        n_states = 2
    drives = rng.random((n_regions, n_states)) < 0.5
    names, sides, states, regions = _meta(layout, n_regions, n_states, policy, drives)
    # masks: each texel belongs to one side (lr-split's requirement), values on 8-bit steps
    masks = np.round(rng.random((n_regions, 6, 5)) * 255) / 255
    left = np.arange(5)[None, :] < 2
    for i, s in enumerate(sides):
        masks[i] *= left if s == "left" else ~left if s == "right" else 1
    packed = wm.pack(masks.astype(np.float32), names, layout=layout, sides=sides)
    tex = np.asarray(packed.textures, np.float32)
    tex = tex[..., None] if tex.ndim == 3 else tex  # array layers are single-channel
    meta = {
        "encoding": "pd",
        "policy": policy,
        "scale": 1.0,
        "states": [{"name": s} for s in states],
        "regions": regions,
        "masks": {
            "layout": layout,
            "textures": [f"m{i}" for i in range(len(tex))],
            "table": packed.table,
        },
    }
    setup = from_meta(WrinkleMeta.from_json(meta), [t.shape[-1] for t in tex])
    w = rng.uniform(-1, 1, n_regions).astype(np.float32)
    wv = setup.weight_vectors(w)
    # one weight per region spread over its states == the general [R, K] form
    d = np.array(setup.region_states, np.float32)
    if policy != "signed":
        np.testing.assert_array_equal(wv, setup.weight_vectors(w[:, None] * d))
    # what the core sums per texel equals the model's region sum on the unpacked masks
    flat = np.moveaxis(tex.reshape(len(tex), -1, tex.shape[-1]), 0, 0)
    rgba = np.zeros(flat.shape[:2] + (4,), np.float32)
    rgba[..., : flat.shape[-1]] = flat
    m = _group_masks(setup, rgba)  # [G, N, 4]
    wq = wv.reshape(setup.n_groups, setup.quads, 4, 4)  # [G, Q, channel, lane]
    s = np.einsum("gnc,gqcj->nqj", m, wq).reshape(m.shape[1], -1)[:, : setup.lanes]
    _, unpacked = wm.unpack(packed.textures, packed.table)
    ww = w[:, None] if policy == "signed" else w[:, None] * d
    expect = model.region_sum(unpacked.reshape(n_regions, -1), ww).T
    np.testing.assert_allclose(s, expect, atol=1e-5)


def test_every_core_define_is_set_and_spelled_per_language():
    a = demo_asset(64)
    meta = {
        "encoding": "pd",
        "policy": "lerp",
        "scale": 0.5,
        "states": [{"name": s} for s in a.state_names],
        "regions": [{"name": r.name, "states": list(r.states)} for r in a.regions],
        "masks": {
            "layout": "rgba",
            "textures": ["m0", "m1"],
            "table": wm.pack(a.masks, list(a.region_names)).table,
        },
    }
    setup = from_meta(WrinkleMeta.from_json(meta), [4, 4])
    d = tpl.defines(setup)
    used = set(
        w
        for w in __import__("re").findall(r"\bWP_[A-Z_]+\b", tpl.CORE + tpl.DECODE_HOOKS)
        if not w.startswith(
            ("WP_ENC_", "WP_POL_", "WP_GATHER_", "WP_LAYOUT_", "WP_FLIP_B", "WP_FLIP_S")
        )
    )
    hooks = {"WP_BASE", "WP_STATE", "WP_MASK", "WP_W", "WP_USED", "WP_LOOP", "WP_REGION_COLOR"}
    hooks |= {"WP_DECODE_BASE", "WP_DECODE_STATE_NORMAL", "WP_DECODE_PD", "WP_DECODE_DIFF"}
    assert used - hooks <= set(d), used - hooks - set(d)
    assert d["WP_SCALE"] == "0.5" and d["WP_POLICY"] == "4" and d["WP_QUADS"] == "1"
    hlsl = tpl.core("hlsl", "[unroll]")
    assert "float4 wp_s[4]" in hlsl and "vec4" not in hlsl and "[unroll] for" in hlsl
    assert "vec4 wp_s[4]" in tpl.core("glsl") and "WP_LOOP" not in tpl.core("glsl")


def _unity_scale_asset(n_states: int = 15, n_regions: int = 135):
    from scipy import ndimage

    a = demo_asset(128)
    names = tuple(f"s{k}" for k in range(n_states))
    pd_b = model.normal_to_pd(a.base)
    states = np.stack(
        [
            model.pd_to_normal(
                pd_b + (0.4 + 0.05 * k) * (model.normal_to_pd(a.states[k % 2]) - pd_b)
            )
            for k in range(n_states)
        ]
    )
    rng = np.random.default_rng(135)
    blobs = ndimage.gaussian_filter(rng.random((n_regions, 32, 32)), (0, 1.5, 1.5))
    m = (blobs > np.percentile(blobs, 85, axis=(1, 2), keepdims=True)).astype(np.float32)
    m = np.stack([np.kron(x, np.ones((4, 4))) for x in m]).astype(np.float32)
    m /= np.maximum(m.sum(axis=0), 1.0)
    rnames = [f"r{i:03d}" for i in range(n_regions)]
    regions = tuple(Region(r, "center", (names[i % n_states],)) for i, r in enumerate(rnames))
    ex = {
        "even": {r: 0.9 for r in rnames[::2]},
        "thirds": {r: 1.0 for r in rnames[1::3]},
        "late_states": {r: 0.7 for i, r in enumerate(rnames) if i % n_states >= 12},
    }
    return replace(a, states=states, state_names=names, masks=m, regions=regions, expressions=ex)


@pytest.mark.gpu
@pytest.mark.parametrize("layout", ["rgba", "array"])
def test_unity_digital_human_scale_renders_like_the_model(layout):
    from wrinklepipe.pipeline.package import PackOptions, package_from_asset
    from wrinklepipe.pipeline.prepare import prepare_mesh
    from wrinklepipe.validate import ValidateOptions, validate
    from wrinklepipe.validate import gl as glw
    from wrinklepipe.validate.loader import input_from_package

    try:
        glw.create_context().release()
    except glw.GLUnavailable as exc:
        pytest.skip(f"no OpenGL: {exc}")
    a = _unity_scale_asset()
    a = replace(a, mesh=prepare_mesh(a.mesh))
    pkg = package_from_asset(a, PackOptions(mask_layout=layout))
    inp = input_from_package(pkg, "unity_scale", "gltf")
    assert len({e.texture for e in inp.channel_table}) == (34 if layout == "rgba" else 135)
    report = validate(inp, ValidateOptions(render_size=128, half_res_check=False))
    assert "skipped" not in report.render, report.render
    for pose, s in report.metrics["gpu_vs_reference_deg"].items():
        assert s["mean"] <= 0.5 and s["p99"] <= 2.0, (pose, s)
    # states 12..14 (the last quad of lanes) really render
    assert report.render["poses"]["late_states"]["changed_pixels"] > 100


def test_a_larger_asset_is_refused_with_one_clear_message():
    n_regions, n_states = 256, 16
    drives = np.ones((n_regions, n_states), bool)
    names, sides, states, regions = _meta("rgba", n_regions, n_states, "clamp01", drives)
    table = [
        {"region": n, "texture": i // 4, "channel": "rgba"[i % 4]} for i, n in enumerate(names)
    ]
    meta = {
        "encoding": "pd",
        "policy": "clamp01",
        "states": [{"name": s} for s in states],
        "regions": regions,
        "masks": {"layout": "rgba", "textures": [f"m{i}" for i in range(64)], "table": table},
    }
    setup = from_meta(WrinkleMeta.from_json(meta), [4] * 64)
    assert setup.n_weight_vectors + setup.n_groups == 64 * 4 * 4 + 64 > MAX_WEIGHT_VECTORS
    with pytest.raises(InputError) as exc:
        setup.check("big.gltf")
    msg = str(exc.value)
    assert msg.startswith("big.gltf: cannot build a wrinkle shader")
    assert "256 regions x 16 states" in msg and f"at most {MAX_WEIGHT_VECTORS}" in msg
    # the Unity Digital Human scale fits
    assert not _small_setup(135, 15).problems()
    assert "17 wrinkle states" in " ".join(_small_setup(8, 17).problems())


def _small_setup(n_regions: int, n_states: int):
    drives = np.ones((n_regions, n_states), bool)
    names, _, states, regions = _meta("rgba", n_regions, n_states, "clamp01", drives)
    n_tex = (n_regions + 3) // 4
    table = [
        {"region": n, "texture": i // 4, "channel": "rgba"[i % 4]} for i, n in enumerate(names)
    ]
    meta = {
        "encoding": "pd",
        "policy": "clamp01",
        "states": [{"name": s} for s in states],
        "regions": regions,
        "masks": {"layout": "rgba", "textures": [f"m{i}" for i in range(n_tex)], "table": table},
    }
    return from_meta(WrinkleMeta.from_json(meta), [4] * n_tex)
