"""A base taken from a glTF material's own normalTexture is counted for off-unit and z < 0
texels like a manifest's base file (ingest's warning, the validator's WP-MAP-007): the
generated avatar with Skin's normal map replaced by one with known bad texels."""

from __future__ import annotations

import io
from types import SimpleNamespace

import numpy as np
from PIL import Image

from wrinklepipe.demo import avatar
from wrinklepipe.gltf.package_write import glb_bytes
from wrinklepipe.pipeline.ingest import ingest_all
from wrinklepipe.sources.manifest import load_manifest
from wrinklepipe.validate.rules_fidelity import check_source_texels


def bad_skin(tmp_path):
    """The avatar source with Skin's normalTexture (image 1) holding 40 texels of length 0.57
    and 7 with z < 0 more than the original; returns the manifest and the texels written."""
    folder = tmp_path / "src"
    for rel, data in avatar.avatar_source_files().items():
        (folder / rel).parent.mkdir(parents=True, exist_ok=True)
        (folder / rel).write_bytes(data)
    doc, data = avatar.avatar_document()
    img = doc["images"][1]
    view = doc["bufferViews"][img["bufferView"]]
    start = view.get("byteOffset", 0)
    q = np.array(Image.open(io.BytesIO(data[start : start + view["byteLength"]])).convert("RGB"))
    q[0, :40] = (128, 128, 200)  # a short normal (length 0.57): off unit, z > 0
    q[1, :7] = (128, 128, 60)  # below the surface
    buf = io.BytesIO()
    Image.fromarray(q).save(buf, format="PNG")
    png = buf.getvalue()
    pad = b"\0" * ((-len(data)) % 4)
    doc["bufferViews"].append(
        {"buffer": 0, "byteOffset": len(data) + len(pad), "byteLength": len(png)}
    )
    img["bufferView"] = len(doc["bufferViews"]) - 1
    new = data + pad + png
    new += b"\0" * ((-len(new)) % 4)
    doc["buffers"][0]["byteLength"] = len(new)
    (folder / "avatar.glb").write_bytes(glb_bytes(doc, new))
    return folder / "manifest.toml", q


def by_hand(q: np.ndarray) -> tuple[int, int]:
    n = (2.0 * q.astype(np.float64) - 255.0) / 255.0
    length = np.linalg.norm(n, axis=-1)
    return int((np.abs(length - 1) > 0.01).sum()), int((n[..., 2] < 0).sum())


def test_the_materials_base_is_counted_for_off_unit_and_below_surface_texels(tmp_path):
    manifest, q = bad_skin(tmp_path)
    non_unit, z_negative = by_hand(q)
    assert z_negative == 7 and non_unit >= 47
    got = ingest_all(load_manifest(manifest))
    stats = got.asset.provenance["maps"]["base"]
    assert "/materials/0/normalTexture" in stats["file"]
    assert (stats["stats"]["non_unit"], stats["stats"]["z_negative"]) == (non_unit, z_negative)
    assert stats["stats"]["texels"] == q.shape[0] * q.shape[1]
    warn = " ".join(got.asset.provenance["warnings"])
    assert f"{non_unit} of {q.shape[0] * q.shape[1]} texels not unit length" in warn
    # the validator's rule on what ingest recorded (convert validates with this asset)
    ctx = SimpleNamespace(
        asset=got.asset, inp=SimpleNamespace(has_source=True, pointer=lambda key: key)
    )
    issues = check_source_texels(ctx)
    assert [i.code for i in issues] == ["WP-MAP-007"]
    assert f"{non_unit} of {q.shape[0] * q.shape[1]} texels" in issues[0].message
    assert f"{z_negative} point below the surface" in issues[0].message
    assert "/materials/0/normalTexture" in issues[0].pointer
