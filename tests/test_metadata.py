"""The typed wrinkle description (wrinklepipe.metadata): JSON round trips, the extension form
against the shipped JSON Schema, and the readers refusing what the schema refuses."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wrinklepipe import model
from wrinklepipe.demo import demo_asset
from wrinklepipe.demo.package import demo_package
from wrinklepipe.errors import InputError, input_error
from wrinklepipe.gltf.package_read import read_wrinkled
from wrinklepipe.gltf.package_write import write_gltf
from wrinklepipe.masks.layouts import LAYOUTS
from wrinklepipe.metadata import (
    EXTENSION,
    CompressedCopy,
    MaskChannel,
    MaskMeta,
    RegionMeta,
    SplitRef,
    StateMeta,
    WrinkleMeta,
    extension_schema,
    schema_problems,
    sorted_expressions,
)
from wrinklepipe.pipeline.package import PackOptions, package_from_asset

MASK_LAYOUTS = ("rgba", "array", "lr-split", "jimenez8")


@pytest.fixture(scope="module")
def asset():
    return demo_asset(16)


@pytest.fixture(scope="module")
def metas(asset):
    return {
        layout: package_from_asset(asset, PackOptions(mask_layout=layout)).meta
        for layout in MASK_LAYOUTS
    }


def _ext_with_index(meta: WrinkleMeta) -> tuple[dict, dict[int, str]]:
    names = sorted({*meta.state_textures, *meta.masks.textures, *meta.texture_copies})
    index = {n: i for i, n in enumerate(names)}
    return meta.to_extension(index), {i: n for n, i in index.items()}


def _err(message: str, pointer: str) -> Exception:
    return input_error("x.gltf", message, pointer)


def test_schema_enums_are_the_models():
    """The schema names the encodings, policies and layouts the model and packer know."""
    props = extension_schema()["properties"]
    assert set(props["encoding"]["enum"]) == set(model.ENCODINGS)
    assert set(props["policy"]["enum"]) == set(model.POLICIES)
    assert set(props["masks"]["properties"]["layout"]["enum"]) <= set(LAYOUTS)


@pytest.mark.parametrize("layout", MASK_LAYOUTS)
def test_json_round_trip_and_schema(metas, layout):
    meta = metas[layout]
    d = meta.to_json()
    assert WrinkleMeta.from_json(json.loads(json.dumps(d))) == meta
    ext, name_of = _ext_with_index(meta)
    assert schema_problems(ext) == []
    back = WrinkleMeta.from_extension(ext, lambda info, key, role: name_of[info["index"]], _err)
    assert back == meta
    assert meta.check(_err) is meta


def test_the_description_is_typed(metas):
    meta = metas["lr-split"]
    assert meta.masks.layout == "lr-split"
    left = next(e for e in meta.masks.table if e.side == "left")
    assert isinstance(left, MaskChannel) and isinstance(left.split, SplitRef)
    assert left.split.channel in "rgba" and left.texture is not None and left.layer is None
    arr = metas["array"].masks.table
    assert [e.index for e in arr] == list(range(len(arr)))  # one layer per region, in order
    with pytest.raises(AttributeError):
        meta.encoding = "diff"  # type: ignore[misc]


@settings(max_examples=25, deadline=None)
@given(
    key=st.sampled_from(["encoding", "policy", "scale", "mapping", "weights", "states", "extra"]),
)
def test_schema_refuses_a_broken_block_naming_the_place(metas, key):
    ext, name_of = _ext_with_index(metas["rgba"])
    bad = {
        "encoding": "jpeg",
        "policy": "max",
        "scale": 0.0,
        "mapping": 7,
        "weights": ["0"],
        "states": [],
        "extra": None,
    }[key]
    if key == "extra":
        ext["unknown"] = 1
    else:
        ext[key] = bad
    problems = schema_problems(ext)
    assert problems
    with pytest.raises(InputError) as exc:
        WrinkleMeta.from_extension(ext, lambda info, k, role: name_of[info["index"]], _err, "/p")
    msg = str(exc.value)
    assert "does not match its schema" in msg
    assert ("/p" if key in ("extra", "states") else f"/p/{key}") in msg


def test_table_entry_with_layer_and_channel_is_refused(metas):
    ext, name_of = _ext_with_index(metas["rgba"])
    ext["masks"]["table"][2]["layer"] = 0  # texture + channel + layer: neither oneOf branch
    assert [p for p, _ in schema_problems(ext)] == ["/masks/table/2"]


def test_gltf_reader_refuses_what_the_schema_refuses(tmp_path):
    pkg = demo_package(16)
    write_gltf(pkg, tmp_path, "a")
    path = tmp_path / "a.gltf"
    doc = json.loads(path.read_text())
    assert read_wrinkled(path).meta == pkg.meta
    doc["materials"][0]["extensions"][EXTENSION]["regions"][1]["side"] = "up"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError) as exc:
        read_wrinkled(path)
    msg = str(exc.value)
    assert str(path) in msg and "'up' is not one of" in msg
    assert f"/materials/0/extensions/{EXTENSION}/regions/1/side" in msg


def test_check_refuses_a_description_off_the_schema(metas):
    meta = replace(metas["rgba"], policy="max")
    with pytest.raises(InputError, match="does not match the schema: 'max' is not one of"):
        meta.check(_err, "/Mat")


_NAME = st.text("abcdefghijklmnopqrstuvwxyz_0123456789", min_size=1, max_size=8)
_WEIGHT = st.floats(-1, 1, allow_nan=False, width=32)


@st.composite
def _metas(draw) -> WrinkleMeta:
    """Any description the schema admits: rgba or array tables, lr-split sides, expressions,
    drivers, weights and compressed copies."""
    states = draw(st.lists(_NAME, min_size=1, max_size=4, unique=True))
    regions = draw(st.lists(_NAME, min_size=1, max_size=9, unique=True))
    layout = draw(st.sampled_from(["rgba", "array", "lr-split"]))
    if layout == "array":
        masks = tuple(f"mask_{i}" for i in range(len(regions)))
        table = tuple(MaskChannel(r, layer=i) for i, r in enumerate(regions))
    else:
        masks = tuple(f"mask_{i}" for i in range((len(regions) + 4) // 4))
        sides = draw(st.lists(st.sampled_from(["left", "right", "center"]), min_size=len(regions),
                              max_size=len(regions)))  # fmt: skip
        split = SplitRef(len(masks) - 1, "a")
        table = tuple(
            MaskChannel(
                r,
                texture=i // 4,
                channel="rgba"[i % 4],
                side=s if layout == "lr-split" else None,
                split=split if layout == "lr-split" and s != "center" else None,
            )
            for i, (r, s) in enumerate(zip(regions, sides))
        )
    region_meta = tuple(
        RegionMeta(r, draw(st.sampled_from(["left", "right", "center"])),
                   tuple(draw(st.lists(st.sampled_from(states), unique=True, max_size=2))))
        for r in regions
    )  # fmt: skip
    expressions = sorted_expressions(
        {e: {r: draw(_WEIGHT) for r in regions} for e in draw(st.lists(_NAME, max_size=3))}
    )
    kinds = st.sampled_from(["curves", "expressions", "blendshapes", "bones", "dynamic"])
    drivers = tuple({"kind": k} for k in draw(st.lists(kinds, max_size=2)))
    state_meta = tuple(StateMeta(s, f"wrinkle_{s}") for s in states)
    copies = tuple(
        CompressedCopy(t, "bc5", "rg", 2, 3, f"compressed/{t}.ktx2", f"compressed/{t}.dds")
        for t in draw(st.lists(st.sampled_from([s.texture for s in state_meta]), unique=True))
    )
    return WrinkleMeta(
        encoding=draw(st.sampled_from(list(model.ENCODINGS))),
        policy=draw(st.sampled_from(list(model.POLICIES))),
        states=state_meta,
        masks=MaskMeta(layout, masks, table),
        regions=region_meta,
        scale=draw(st.floats(0.125, 8, width=32)),
        mapping=draw(st.sampled_from([1, 2])),
        expressions=expressions,
        drivers=drivers,
        weights=tuple(draw(_WEIGHT) for _ in regions),
        compressed=copies,
    )


@settings(max_examples=60, deadline=None)
@given(meta=_metas())
def test_every_description_round_trips_through_both_json_forms(meta):
    """Law: from_json . to_json and from_extension . to_extension are the identity, and the
    extension form of a description the schema admits has no schema problem."""
    assert WrinkleMeta.from_json(json.loads(json.dumps(meta.to_json()))) == meta
    ext, name_of = _ext_with_index(meta)
    assert schema_problems(ext) == []
    ext = json.loads(json.dumps(ext))
    back = WrinkleMeta.from_extension(ext, lambda info, key, role: name_of[info["index"]], _err)
    assert back == meta
