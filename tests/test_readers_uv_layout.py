"""xatlas's UV layout made in a child process (wrinklepipe.readers.meshes._uv_layouts): the very
arrays ``xatlas.parametrize`` returns in this process, a child that hangs stopped and tried
again, a child that fails reported by its last line."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
import trimesh
import xatlas

from wrinklepipe.readers import meshes


def _sphere(subdivisions: int = 3) -> tuple[np.ndarray, np.ndarray]:
    m = trimesh.creation.icosphere(subdivisions=subdivisions)
    return np.ascontiguousarray(m.vertices, np.float32), np.ascontiguousarray(m.faces, np.uint32)


def test_the_child_lays_out_what_xatlas_parametrize_does_for_each_part() -> None:
    parts = [_sphere(), _sphere(1), _sphere(2)]
    parts[1] = (parts[1][0] * 2 + 1, parts[1][1])  # another size and place
    layouts = meshes._uv_layouts(parts)
    assert len(layouts) == 3
    for (positions, indices), got in zip(parts, layouts, strict=True):
        want = xatlas.parametrize(positions, indices)
        assert len(got) == 3
        for g, w in zip(got, want, strict=True):
            assert g.dtype == w.dtype and np.array_equal(g, w)
        assert got[1].shape == indices.shape and got[2].shape == (len(got[0]), 2)
        assert 0.0 <= got[2].min() and got[2].max() <= 1.0
    assert meshes._uv_layouts([]) == []


def test_a_child_that_never_answers_is_stopped_and_tried_again(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    calls = tmp_path / "calls"
    child = tmp_path / "hangs.py"
    child.write_text(
        f"import time\nwith open({str(calls)!r}, 'a') as f: f.write('x')\ntime.sleep(60)\n"
    )
    monkeypatch.setattr(meshes, "UV_LAYOUT_CHILD", child)
    monkeypatch.setattr(meshes, "UV_LAYOUT_SECONDS", 1.0)
    monkeypatch.setattr(meshes, "UV_LAYOUT_SECONDS_PER_TRIANGLE", 0.0)
    t0 = time.monotonic()
    with pytest.raises(RuntimeError, match=r"did not lay out UVs \(1280 triangles\) in 1 s"):
        meshes._uv_layouts([_sphere()])
    assert calls.read_text() == "xx"  # two tries
    assert time.monotonic() - t0 < 30  # both killed at their limit, not waited for


def test_a_child_that_fails_is_reported_by_its_last_line(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    child = tmp_path / "fails.py"
    child.write_text("raise ValueError('no charts in this mesh')\n")
    monkeypatch.setattr(meshes, "UV_LAYOUT_CHILD", child)
    with pytest.raises(RuntimeError, match="could not lay out UVs .*no charts in this mesh"):
        meshes._uv_layouts([_sphere()])
