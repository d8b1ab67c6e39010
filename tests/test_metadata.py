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
from wrinklepipe.io.gltf_read import read_gltf
from wrinklepipe.io.gltf_write import write_gltf
from wrinklepipe.io.package import PackOptions, package_from_asset
from wrinklepipe.masks.layouts import LAYOUTS
from wrinklepipe.metadata import (
    EXTENSION,
    MaskChannel,
    SplitRef,
    WrinkleMeta,
    extension_schema,
    schema_problems,
)

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
    assert read_gltf(path).meta == pkg.meta
    doc["materials"][0]["extensions"][EXTENSION]["regions"][1]["side"] = "up"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError) as exc:
        read_gltf(path)
    msg = str(exc.value)
    assert str(path) in msg and "'up' is not one of" in msg
    assert f"/materials/0/extensions/{EXTENSION}/regions/1/side" in msg


def test_check_refuses_a_description_off_the_schema(metas):
    meta = replace(metas["rgba"], policy="max")
    with pytest.raises(InputError, match="does not match the schema: 'max' is not one of"):
        meta.check(_err, "/Mat")
