"""OBJ ingest: vertex splits at UV seams, fan triangulation, V flip, relative indices, errors."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wrinklepipe.errors import InputError
from wrinklepipe.readers.meshes import LoadOptions, load_mesh, load_meshes

OBJ = """# two quads sharing an edge that is a UV seam
o left
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 2 0 0
v 2 1 0
vt 0 0
vt 0.5 0
vt 0.5 1
vt 0 1
vt 0.6 0
vt 1 0
vt 1 1
vt 0.6 1
vn 0 0 1
f 1/1/1 2/2/1 3/3/1 4/4/1
o right
f 2/5/1 5/6/1 6/7/1 -4/8/1
"""


def test_obj_parts_splits_and_triangulation(tmp_path):
    f = tmp_path / "q.obj"
    f.write_text(OBJ)
    parts = load_meshes(f)
    assert [p.name for p in parts] == ["left", "right"]
    m = load_mesh(f)
    assert m.vertex_count == 8 and m.triangle_count == 4
    np.testing.assert_array_equal(parts[1].positions[3], [1, 1, 0])  # -4 = v 3
    np.testing.assert_allclose(parts[0].uvs[3], [0, 0])  # vt (0, 1) flipped to glTF v
    assert any("fan-triangulated 1 polygon" in n for n in parts[0].notes)
    np.testing.assert_allclose(m.normals, np.tile([0, 0, 1], (8, 1)))


def test_obj_errors(tmp_path):
    f = tmp_path / "bad.obj"
    f.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n")
    with pytest.raises(InputError, match="out of range"):
        load_mesh(f)
    f.write_text("v 0 0 0\nv 1 0 0\n")
    with pytest.raises(InputError, match="no faces"):
        load_mesh(f)
    f.write_text("v 0 nan 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(InputError, match="NaN"):
        load_mesh(f)
    # 1e39 is finite as a double but infinite as the float32 a mesh is stored as (3.4028e38)
    f.write_text("v 0 0 0\nv 1 0 0\nv 0 1e39 0\nf 1 2 3\n")
    with pytest.raises(InputError, match=r"position 3 has a value beyond float32's range"):
        load_mesh(f)
    f.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 inf\nvt 0 1\nf 1/1 2/2 3/3\n")
    with pytest.raises(InputError, match="UV 2 is NaN or infinite"):
        load_mesh(f)
    f.write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 4\n")
    m = load_mesh(f)  # the collinear triangle is skipped and counted; xatlas UVs noted
    assert m.triangle_count == 1
    assert any("skipped 1 degenerate" in n for n in m.notes)
    assert any("xatlas" in n for n in m.notes)
    with pytest.raises(InputError, match="unknown mesh format"):
        load_mesh(tmp_path / "x.fbx")


LINE = st.one_of(
    st.builds(lambda a, b, c: f"v {a} {b} {c}", *[st.floats(allow_nan=True) | st.just("x")] * 3),
    st.builds(lambda a, b: f"vt {a} {b}", st.floats(-2, 2), st.floats(-2, 2)),
    st.just("vn 0 0 1"),
    st.builds(
        lambda ids: "f " + " ".join(ids),
        st.lists(
            st.builds(
                lambda v, t, n: f"{v}/{t}/{n}",
                st.integers(-6, 8),
                st.integers(-3, 3) | st.just(""),
                st.integers(-2, 2) | st.just(""),
            ),
            min_size=1,
            max_size=5,
        ),
    ),
    st.sampled_from(["o part", "g", "# comment", "", "s off", "usemtl x", "f", "v"]),
)


@settings(max_examples=150, deadline=None)
@given(lines=st.lists(LINE, max_size=14))
def test_random_obj_never_tracebacks(tmp_path_factory, lines):
    f = tmp_path_factory.mktemp("obj") / "r.obj"
    f.write_text("\n".join(lines) + "\n")
    try:
        m = load_mesh(f, LoadOptions(generate_uvs=False))
    except InputError:
        return
    assert m.triangle_count > 0 and int(m.indices.max()) < m.vertex_count
    assert np.isfinite(m.positions).all()
