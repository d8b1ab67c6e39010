"""Write the demo character as the files an artist would hand over, plus its manifest.

``write_demo_source(folder)`` writes::

    manifest.toml         the source manifest (wrinklepipe/manifest@1)
    head.glb              the mesh: positions, normals, UVs, 8 named morph targets
    base_normal.png       16-bit RGB tangent-space normals, OpenGL (+Y)
    wrinkle_stretch.png   16-bit: the face in the stretch pose (base detail included)
    wrinkle_compress.png  16-bit: the face in the compress pose
    masks/<region>.png    8-bit grayscale masks, one per Jimenez zone, at a quarter of the map size

``demo_source_dir()`` generates it once into a cache folder (``$WRINKLEPIPE_CACHE`` or
``~/.cache/wrinklepipe``) and returns the manifest path; later calls reuse it.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pygltflib

from wrinklepipe.atomic import staged_folder, write_bytes
from wrinklepipe.demo.character import DEMO_VERSION, DemoCharacter, generate
from wrinklepipe.demo.colors import demo_colors
from wrinklepipe.io.images import write_image
from wrinklepipe.io.png import png_bytes
from wrinklepipe.staging import output_lock


def cache_root() -> Path:
    """The folder generated data is cached in."""
    env = os.environ.get("WRINKLEPIPE_CACHE")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "wrinklepipe"


def _box_down(a: np.ndarray, f: int) -> np.ndarray:
    h, w = a.shape[-2:]
    return a.reshape(a.shape[:-2] + (h // f, f, w // f, f)).mean(axis=(-3, -1))


def demo_glb_bytes(c: DemoCharacter) -> bytes:
    """The demo mesh as a GLB (positions, normals, UVs, indices, named morph targets)."""
    m = c.mesh
    blobs: list[bytes] = []
    views: list[pygltflib.BufferView] = []
    accessors: list[pygltflib.Accessor] = []
    offset = 0

    def add(arr: np.ndarray, kind: str, ctype: int, target: int | None, minmax: bool) -> int:
        nonlocal offset
        data = np.ascontiguousarray(arr).tobytes()
        pad = (-len(data)) % 4
        views.append(
            pygltflib.BufferView(buffer=0, byteOffset=offset, byteLength=len(data), target=target)
        )
        blobs.append(data + b"\0" * pad)
        offset += len(data) + pad
        acc = pygltflib.Accessor(
            bufferView=len(views) - 1,
            componentType=ctype,
            count=int(arr.shape[0]),
            type=kind,
        )
        if minmax:
            acc.min = [float(x) for x in arr.min(axis=0)]
            acc.max = [float(x) for x in arr.max(axis=0)]
        accessors.append(acc)
        return len(accessors) - 1

    f32, u32 = pygltflib.FLOAT, pygltflib.UNSIGNED_INT
    vb, ib = pygltflib.ARRAY_BUFFER, pygltflib.ELEMENT_ARRAY_BUFFER
    pos = add(m.positions.astype(np.float32), "VEC3", f32, vb, True)
    nrm = add(m.normals.astype(np.float32), "VEC3", f32, vb, False)
    uv = add(m.uvs.astype(np.float32), "VEC2", f32, vb, False)
    idx = add(m.indices.reshape(-1).astype(np.uint32), "SCALAR", u32, ib, False)
    targets = [
        {"POSITION": add(m.morph_deltas[i].astype(np.float32), "VEC3", f32, vb, True)}
        for i in range(len(m.morph_names))
    ]
    prim = pygltflib.Primitive(
        attributes=pygltflib.Attributes(POSITION=pos, NORMAL=nrm, TEXCOORD_0=uv),
        indices=idx,
        targets=targets,
    )
    gltf = pygltflib.GLTF2(
        asset=pygltflib.Asset(version="2.0", generator="wrinklepipe demo"),
        scene=0,
        scenes=[pygltflib.Scene(nodes=[0])],
        nodes=[pygltflib.Node(mesh=0, name="demo_head")],
        meshes=[
            pygltflib.Mesh(
                name="demo_head",
                primitives=[prim],
                weights=[0.0] * len(m.morph_names),
                extras={"targetNames": list(m.morph_names)},
            )
        ],
        accessors=accessors,
        bufferViews=views,
        buffers=[pygltflib.Buffer(byteLength=offset)],
    )
    gltf.set_binary_blob(b"".join(blobs))
    return b"".join(gltf.save_to_bytes())


def manifest_text(c: DemoCharacter, size: int) -> str:
    """The demo's manifest.toml."""
    lines = [
        f"# wrinklepipe demo character (generated; seed {c.seed})",
        'schema = "wrinklepipe/manifest@1"',
        'name = "demo_head"',
        'mesh = "head.glb"',
        'base = "base_normal.png"',
        'base_color = "base_color.png"  # the skin; each state\'s colour blends over it',
        'convention = "opengl"',
        'encoding = "pd"',
        'policy = "clamp01"',
        'pd_scale = "auto"',
        "states_include_base = true",
        'expressions = "jimenez"',
        "",
        "[resolution]",
        f"base = {size}",
        'wrinkle = "auto"  # the smallest size whose blended error meets the budget',
        'mask = "auto"  # the smallest mask size within the budget',
        'color = "auto"  # the colour states\' size, by CIEDE2000 within the colour budget',
        "",
        "[budget]",
        "max_mean_deg = 0.5",
        "max_p99_deg = 2.0",
        "",
    ]
    tint = {"stretch": "pale: blood pushed out", "compress": "flushed: blood pooling"}
    for name in c.state_names:
        lines += ["[[states]]", f'name = "{name}"', f'map = "wrinkle_{name}.png"']
        lines += [f'color = "color_{name}.png"  # {tint.get(name, "its colour")}', ""]
    for name, side in zip(c.region_names, c.region_sides):
        lines += [
            "[[regions]]",
            f'name = "{name}"',
            f'mask = "masks/{name}.png"',
            f'side = "{side}"',
            "",
        ]
    lines += [
        "# Expression keys over time (seconds): neutral, then each of Table 1.1, then a compound.",
        "[[drivers]]",
        'kind = "expressions"',
        'interpolation = "linear"',
        "fps = 24",
        "[drivers.keys]",
    ]
    names = list(c.expressions)
    for i, e in enumerate(names):
        t = float(i + 1)
        lines.append(f"{e} = [[{t - 1.0}, 0.0], [{t}, 1.0], [{t + 1.0}, 0.0]]")
    return "\n".join(lines) + "\n"


def write_demo_source(folder: str | Path, size: int = 1024) -> Path:
    """Write the demo source files into ``folder``; return the manifest path."""
    folder = Path(folder)
    c = generate(size)
    folder.mkdir(parents=True, exist_ok=True)
    write_bytes(folder / "head.glb", demo_glb_bytes(c))
    write_image(folder / "base_normal.png", c.base_normal * 0.5 + 0.5, bits=16)
    for k, name in enumerate(c.state_names):
        write_image(folder / f"wrinkle_{name}.png", c.wrinkled_normal(k) * 0.5 + 0.5, bits=16)
    masks = _box_down(c.masks, 4) if size >= 16 else c.masks
    for name, mask in zip(c.region_names, masks):
        write_image(folder / "masks" / f"{name}.png", mask, bits=8)
    colors = demo_colors(c.base_height, c.state_names)  # sRGB, as painted
    write_bytes(folder / "base_color.png", png_bytes(colors.base))
    for j, k in enumerate(colors.state_index):
        write_bytes(folder / f"color_{c.state_names[k]}.png", png_bytes(colors.states[j]))
    manifest = folder / "manifest.toml"
    write_bytes(manifest, manifest_text(c, size).encode("utf-8"))
    return manifest


def demo_source_dir(size: int = 1024) -> Path:
    """The cached demo source (generated on first use); returns its manifest path."""
    target = cache_root() / f"demo-v{DEMO_VERSION}-{size}"
    manifest = target / "manifest.toml"
    if manifest.is_file():
        return manifest
    target.parent.mkdir(parents=True, exist_ok=True)
    with output_lock(target, wait=True):  # parallel workers: one writes, the others wait
        if not manifest.is_file():
            with staged_folder(target, force=True) as tmp:
                write_demo_source(tmp, size)
    return manifest
