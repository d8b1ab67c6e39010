"""Colour states for whole characters in tests: the generated avatar's Skin material with a pale
(stretch) and a flushed (compress) colour map made from its own base colour."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wrinklepipe.demo import avatar, colors
from wrinklepipe.io.png import png_bytes, png_pixels


def avatar_skin_color() -> np.ndarray:
    """The avatar's Skin baseColorTexture texels (image 0 of its GLB), as stored."""
    doc, data = avatar.avatar_document()
    view = doc["bufferViews"][doc["images"][0]["bufferView"]]
    start = view.get("byteOffset", 0)
    return png_pixels(data[start : start + view["byteLength"]])


def with_colors(text: str, colors_of: dict[str, str], extra: str = "") -> str:
    """A manifest's text with ``color = FILE`` added to the states named in ``colors_of`` (and
    ``extra`` lines after the top-level keys)."""
    out = []
    state = None
    for line in text.splitlines():
        out.append(line)
        if line.startswith("pd_scale") and extra:
            out.append(extra)
        if line.startswith("name = ") and out[-2:-1] == ["[[states]]"]:
            state = line.split('"')[1]
            if state in colors_of:
                out.append(f'color = "{colors_of[state]}"')
    return "\n".join(out) + "\n"


def write_avatar_color_source(
    folder: Path,
    states: dict[str, np.ndarray] | None = None,
    extra: str = "",
    files: dict[str, bytes] | None = None,
) -> Path:
    """The avatar's source folder with colour states (default: ``stretch`` pale, ``compress``
    flushed, 16-bit-free 8-bit PNGs at the base colour's size); the manifest's path. ``files``:
    more files to write (e.g. a ``base_color``)."""
    folder.mkdir(parents=True, exist_ok=True)
    for rel, data in avatar.avatar_source_files().items():
        (folder / rel).parent.mkdir(parents=True, exist_ok=True)
        (folder / rel).write_bytes(data)
    base = avatar_skin_color()
    if states is None:
        states = {"stretch": colors.pale(base), "compress": colors.flushed(base)}
    names = {}
    for name, texels in states.items():
        names[name] = f"color_{name}.png"
        (folder / names[name]).write_bytes(png_bytes(texels))
    for rel, data in (files or {}).items():
        (folder / rel).write_bytes(data)
    manifest = folder / "manifest.toml"
    manifest.write_text(with_colors(avatar.manifest_text(), names, extra), encoding="utf-8")
    return manifest


def cesium_skin_texels(mesh: Path) -> np.ndarray:
    """CesiumMan's baseColorTexture texels (its JPEG, decoded as the pipeline reads it)."""
    from wrinklepipe.gltf.document import read_document
    from wrinklepipe.gltf.images import texture_texels

    doc = read_document(mesh)
    index = doc.array("materials")[0]["pbrMetallicRoughness"]["baseColorTexture"]["index"]
    return texture_texels(doc, index)[..., :3]


def write_cesium_color_source(folder: Path, mesh: Path, size: int = 256) -> Path:
    """The fidelity fixture on CesiumMan (``wrinklepipe.demo.face_fixture``) at ``size`` with
    colour states over the character's own skin texture: ``stretch`` pale, ``compress``
    flushed (painted on the texture's 1024^2 layout), the colour size and format on auto."""
    from wrinklepipe.demo import face_fixture as ff

    m = ff.write_fixture_source(folder, mesh, size)
    skin = cesium_skin_texels(mesh)
    (folder / "color_stretch.png").write_bytes(png_bytes(colors.pale(skin)))
    (folder / "color_compress.png").write_bytes(png_bytes(colors.flushed(skin)))
    text = m.read_text(encoding="utf-8")
    text = with_colors(text, {"stretch": "color_stretch.png", "compress": "color_compress.png"})
    text = text.replace('mask = "auto"\n', 'mask = "auto"\ncolor = "auto"\n', 1)
    m.write_text(text, encoding="utf-8")
    return m
