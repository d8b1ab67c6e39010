""" "Nothing is lost": a converted document compared with its source by an independent reader.

pygltflib parses both files and :mod:`gltf_reference` decodes accessors with struct, so nothing
of wrinklepipe's reading is used. :func:`compare` asserts that every element of the source is
in the output with equal data and returns what was added, for the tests to check exactly."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import gltf_reference as ref
import numpy as np

EXTENSION = "WRINKLEPIPE_wrinkle_maps"
WRINKLE_ATTRIBUTES = {"TANGENT", "_WRINKLE_VERTEX_ID"}


@dataclass
class Added:
    """What the output has that the source had not."""

    attributes: dict[tuple[int, int], set[str]] = field(default_factory=dict)
    materials: list[int] = field(default_factory=list)  # materials carrying the extension
    clones: dict[int, int] = field(default_factory=dict)  # clone index -> source material
    textures: int = 0
    images: int = 0
    animations: list[str] = field(default_factory=list)
    repaired: set[int] = field(default_factory=set)  # source accessors replaced by a repair


def _data(g, path, i):
    return ref.accessor(g, path, i)


def _same_accessor(g0, p0, i, g1, p1, j) -> None:
    a0, a1 = g0.accessors[i], g1.accessors[j]
    assert (a0.componentType, a0.type, a0.count, a0.normalized) == (
        a1.componentType,
        a1.type,
        a1.count,
        a1.normalized,
    ), f"accessor {i}"
    np.testing.assert_array_equal(_data(g0, p0, i), _data(g1, p1, j), err_msg=f"accessor {i}")


def _without(d: dict, *keys: str) -> dict:
    return {k: v for k, v in d.items() if k not in keys}


def compare(source: Path, output: Path, base_replaced: bool = True) -> Added:
    """Assert that ``output`` holds every element of ``source`` unchanged; return the additions.

    Allowed differences: attributes added to primitives (returned), WEIGHTS renormalised into new
    accessors (the spec's sum-to-1 repair; checked equal to the source divided by its sum), the
    extension on wrinkled materials (and, with ``base_replaced``, their normalTexture), cloned
    materials appended, textures / images / samplers / animations / accessors appended."""
    g0, g1 = ref.load(source), ref.load(output)
    j0, j1 = json.loads(g0.to_json()), json.loads(g1.to_json())  # pygltflib's own JSON
    added = Added()
    # every source accessor keeps its index, type and values
    assert len(g1.accessors) >= len(g0.accessors)
    for i in range(len(g0.accessors)):
        _same_accessor(g0, source, i, g1, output, i)
    # scenes and nodes: names, hierarchy, TRS / matrix, mesh, skin, weights, extras: identical
    for key in ("scene", "scenes", "nodes", "cameras", "skins"):
        # names, hierarchy, TRS / matrix, mesh, skin, weights, extras; skins' joints and
        # skeleton (inverse bind matrices: through the accessor check above)
        assert j1.get(key) == j0.get(key), key
    # meshes
    assert len(j1["meshes"]) == len(j0["meshes"])
    for mi, (m0, m1) in enumerate(zip(j0["meshes"], j1["meshes"])):
        assert _without(m1, "primitives") == _without(m0, "primitives")
        assert len(m1["primitives"]) == len(m0["primitives"])
        for pi, (d0, d1) in enumerate(zip(m0["primitives"], m1["primitives"])):
            assert _without(d1, "attributes", "material") == _without(d0, "attributes", "material")
            a0, a1 = d0["attributes"], d1["attributes"]
            assert set(a0) <= set(a1), f"mesh {mi} primitive {pi} lost attributes"
            for k, i in a0.items():
                if a1[k] != i:  # only a repair may point elsewhere
                    assert k.startswith("WEIGHTS_"), f"mesh {mi}/{pi} {k} moved"
                    w0 = _data(g0, source, i)
                    w1 = _data(g1, output, a1[k])
                    np.testing.assert_allclose(
                        w1, w0 / np.maximum(w0.sum(axis=1, keepdims=True), 1e-30), atol=1e-6
                    )
                    added.repaired.add(i)
            if set(a1) - set(a0):
                added.attributes[(mi, pi)] = set(a1) - set(a0)
            if d1.get("material") != d0.get("material"):
                assert d1["material"] >= len(j0.get("materials", [])), f"{mi}/{pi} material moved"
                added.clones[d1["material"]] = d0.get("material")
    # materials: the source's as they were, the extension (and base) on the wrinkled ones
    mats0, mats1 = j0.get("materials", []), j1.get("materials", [])
    assert len(mats1) >= len(mats0)
    for i, d1 in enumerate(mats1):
        if EXTENSION in (d1.get("extensions") or {}):
            added.materials.append(i)
        if i >= len(mats0):
            assert i in added.clones, f"material {i} added but used by no moved primitive"
            d0 = mats0[added.clones[i]] if added.clones[i] is not None else {}
            assert d1["name"] == f"{d0.get('name')} (wrinkled)" or not d0
        else:
            d0 = mats0[i]
        ext1 = dict(d1.get("extensions") or {})
        ext1.pop(EXTENSION, None)
        assert ext1 == dict(d0.get("extensions") or {}), f"material {i} extensions"
        skip = ("extensions", "name") + (("normalTexture",) if base_replaced else ())
        if i in added.materials:
            assert _without(d1, *skip) == _without(d0, *skip), f"material {i}"
        else:  # a clone keeps everything but its name (checked above)
            own = ("extensions", "name") if i >= len(mats0) else ("extensions",)
            assert _without(d1, *own) == _without(d0, *own), f"material {i}"
    # textures, samplers and images: the source's unchanged (image bytes byte for byte)
    for key in ("textures", "samplers"):
        n0 = len(j0.get(key, []))
        assert j1.get(key, [])[:n0] == j0.get(key, []), key
    for i, img in enumerate(j0.get("images", [])):
        out = j1["images"][i]
        assert out.get("name") == img.get("name"), f"image {i}"
        assert ref.image_bytes(g1, output, i) == ref.image_bytes(g0, source, i), f"image {i}"
    added.textures = len(j1.get("textures", [])) - len(j0.get("textures", []))
    added.images = len(j1.get("images", [])) - len(j0.get("images", []))
    # animations: the source's with equal channels and samplers (keys: accessors above)
    anims0, anims1 = j0.get("animations", []), j1.get("animations", [])
    assert anims1[: len(anims0)] == anims0
    added.animations = [a.get("name") for a in anims1[len(anims0) :]]
    used0 = set(g0.extensionsUsed or [])
    assert used0 <= set(g1.extensionsUsed or [])
    assert set(g1.extensionsRequired or []) == set(g0.extensionsRequired or [])
    return added
