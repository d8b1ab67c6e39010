"""The project's own writers (glTF, USD) read back by mesh ingest: positions, UVs (V flipped
both ways), normals, morph targets and vertex IDs survive exactly."""

from __future__ import annotations

import numpy as np
import pytest

from wrinklepipe.readers.meshes import load_mesh


@pytest.fixture(scope="module")
def package():
    from wrinklepipe.demo.package import demo_package

    return demo_package(64)


@pytest.mark.parametrize("name", ["head.glb", "head.usda"])
def test_written_asset_reads_back(package, tmp_path, name):
    from wrinklepipe.gltf.package_write import write_glb
    from wrinklepipe.usd.package_write import write_usd

    path = tmp_path / name
    if name.endswith(".glb"):
        write_glb(package, path)
    else:
        write_usd(package, path)
    src = package.mesh
    m = load_mesh(path)
    assert m.vertex_count == src.vertex_count
    np.testing.assert_array_equal(m.positions, src.positions)
    np.testing.assert_allclose(m.uvs, src.uvs, atol=1e-6)
    np.testing.assert_allclose(m.normals, src.normals, atol=1e-6)
    np.testing.assert_array_equal(m.vertex_ids, src.vertex_ids)
    assert m.morph_names == src.morph_names
    np.testing.assert_allclose(m.morph_deltas, src.morph_deltas, atol=1e-7)
    np.testing.assert_array_equal(np.sort(m.indices, axis=1), np.sort(src.indices, axis=1))
