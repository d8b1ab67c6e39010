"""The wrinkled part of a real multi-part character: material selection (every bad case one
clear message listing the materials) and attributes added to the wrinkled primitives only,
checked by an independent reader (pygltflib) and the Khronos validator."""

from __future__ import annotations

import gltf_reference as ref
import numpy as np
import pytest
from wrinkle_setups import ROBOT

from wrinklepipe.errors import InputError
from wrinklepipe.gltf.document import read_document
from wrinklepipe.gltf.repair import repair
from wrinklepipe.gltf.wrinkled import (
    VERTEX_ID_ATTRIBUTE,
    add_wrinkle_attributes,
    select_materials,
    wrinkled_primitives,
)
from wrinklepipe.gltf.write import write_document
from wrinklepipe.io import khronos

needs_robot = pytest.mark.skipif(not ROBOT.is_file(), reason="../shared/data is absent")


@needs_robot
@pytest.mark.parametrize(
    "wanted, message",
    [
        (None, "has 3 materials; name the wrinkled one"),
        ("Skin", "no material 'Skin'"),
        (["Grey", "Nope"], "no material 'Nope'"),
    ],
)
def test_bad_material_names_list_the_materials(wanted, message):
    doc = read_document(ROBOT)
    with pytest.raises(InputError) as exc:
        select_materials(doc, wanted, "m.toml")
    text = str(exc.value)
    assert message in text and "m.toml" in text
    assert "'Black' (Head/2)" in text  # every material with its primitives
    assert "'Grey' (Foot.L/0, Torso/0, Head/0, Foot.R/0, Hand.R/1, Hand.L/1)" in text


@needs_robot
def test_ambiguous_and_unused_materials_are_refused():
    doc = read_document(ROBOT)
    doc.gltf["materials"][2]["name"] = "Grey"
    with pytest.raises(InputError, match="ambiguous.*materials 0, 2 share it"):
        select_materials(doc, "Grey")
    doc = read_document(ROBOT)
    doc.gltf["materials"].append({"name": "Spare"})
    with pytest.raises(InputError, match="'Spare' is used by no primitive"):
        select_materials(doc, "Spare")


@needs_robot
@pytest.mark.skipif(not khronos.available(), reason="gltf-validator missing")
def test_only_the_wrinkled_primitives_change(tmp_path):
    doc = read_document(ROBOT)
    repair(doc)
    mats = select_materials(doc, "Black")
    refs = wrinkled_primitives(doc, mats)
    assert [(r.mesh, r.primitive) for r in refs] == [(2, 2)]  # the head's black face plate
    parts = add_wrinkle_attributes(doc, refs)
    out = tmp_path / "robot.glb"
    write_document(doc, out)
    assert khronos.validate_gltf(out)["issues"]["numErrors"] == 0
    a, b = ref.load(ROBOT), ref.load(out)
    for i in range(len(a.accessors)):  # every source accessor is still there, equal
        assert np.array_equal(ref.accessor(a, ROBOT, i), ref.accessor(b, out, i)), i
    for mi, (ma, mb) in enumerate(zip(a.meshes, b.meshes)):
        for pi, (pa, pb) in enumerate(zip(ma.primitives, mb.primitives)):
            da = {k: v for k, v in vars(pa.attributes).items() if v is not None}
            db = {k: v for k, v in vars(pb.attributes).items() if v is not None}
            added = set(db) - set(da)
            if (mi, pi) == (2, 2):
                assert added == {"TANGENT", "TEXCOORD_0", VERTEX_ID_ATTRIBUTE}
                assert all(da[k] == db[k] for k in da)  # its own attributes untouched
            elif mi in (12, 13):  # the hands' repaired weights
                assert added == set() and da.keys() == db.keys()
            else:
                assert da == db, (mi, pi)
            assert pa.indices == pb.indices and pa.material == pb.material
            assert pa.targets == pb.targets
    p = b.meshes[2].primitives[2]
    custom = {k: v for k, v in p.attributes.__dict__.items() if k.startswith("_WRINKLE")}
    assert list(custom) == [VERTEX_ID_ATTRIBUTE]
    ids = ref.accessor(b, out, custom[VERTEX_ID_ATTRIBUTE])[:, 0]
    pos = ref.accessor(b, out, p.attributes.POSITION)
    # vertices at the same position (hard-edge splits) share an ID, different positions do not
    _, first = np.unique(pos.round(6), axis=0, return_inverse=True)
    assert len(np.unique(ids)) == len(np.unique(first))
    t = ref.accessor(b, out, p.attributes.TANGENT)
    n = ref.accessor(b, out, p.attributes.NORMAL)
    assert np.allclose(np.linalg.norm(t[:, :3], axis=1), 1, atol=1e-5)
    assert np.abs(np.einsum("ij,ij->i", t[:, :3], n)).max() < 1e-3
    assert parts[0].notes[0].startswith("no UVs: added TEXCOORD_0")


@needs_robot
def test_custom_attributes_of_another_shape_are_kept_and_noted():
    """A source's own custom attribute that is not SCALAR FLOAT (a VEC3 here) stays as it is
    beside the added SCALAR vertex IDs, and the part's notes say Blender's importer will fail
    on (or drop) it; a SCALAR FLOAT one gives no note."""
    for kind, noted in (("VEC3", True), ("SCALAR", False)):
        doc = read_document(ROBOT)
        repair(doc)
        refs = wrinkled_primitives(doc, select_materials(doc, "Black"))
        attrs = doc.primitive(refs[0])["attributes"]
        n = doc.gltf["accessors"][attrs["POSITION"]]["count"]
        attrs["_PAINT"] = doc.add_accessor(np.zeros((n, 3 if kind == "VEC3" else 1), np.float32))
        parts = add_wrinkle_attributes(doc, refs)
        note = [x for x in parts[0].notes if "_PAINT" in x]
        assert doc.gltf["accessors"][attrs["_PAINT"]]["type"] == kind
        assert len(note) == int(noted), parts[0].notes
        if noted:
            assert "not SCALAR FLOAT" in note[0] and "Blender 5's glTF importer" in note[0]
