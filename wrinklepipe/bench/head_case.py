"""The film-scale case: a real head's UV layout with wrinkle maps at any size, written band by
band (``wrinklepipe bench scale``, docs/scale.md).

The mesh is Cesium's *CesiumMan* (Khronos glTF sample, ``../shared/data``): an artist's UV
layout whose face plate is a disc of about 7 % of the UV square. The maps are the fidelity
fixture's (:mod:`wrinklepipe.demo.face_fixture`) at ``size`` x ``size``: a 16-bit base of
pore-scale relief with a scar, two 16-bit wrinkle states (stretch: forehead lines; compress:
glabella, crow's feet, nose and nasolabial creases) that hold the base, eight 8-bit soft masks
at full size, six expressions, and a manifest with every choice on ``auto`` (wrinkle and mask
sizes, PD scale, block formats) and the fixture's budget. The relief is defined in UV units,
so the case is the same face at every size (a scanned head baked at 1K or 8K).

Written band by band (:data:`BAND` rows of every map at a time, each PNG streamed through
:class:`wrinklepipe.io.png.PngRows`), so making the 8192² case needs about 100 MB however
large it is. The mesh is referenced where it lies (convert it with ``--allow-root`` on its
folder), never copied.
"""

from __future__ import annotations

import contextlib
import hashlib
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from wrinklepipe import model
from wrinklepipe.atomic import staged_folder, temp_path, write_bytes
from wrinklepipe.demo import face_fixture as ff
from wrinklepipe.demo.source import cache_root
from wrinklepipe.io.images import quantize
from wrinklepipe.io.png import DEFAULT_PNG_LEVEL, PngRows
from wrinklepipe.paths import ROOT
from wrinklepipe.readers.meshes import load_mesh

CASE_VERSION = 1
#: Rows of every map generated and written at a time.
BAND = 256
#: CesiumMan under ``../shared/data`` beside the checkout.
MESH = ROOT.parent / "shared" / "data" / ff.MESH_RELPATH
SIZES = (1024, 2048, 4096, 8192)


def write_head_case(folder: str | Path, size: int, mesh_path: str | Path = MESH) -> Path:
    """Write the case at ``size`` x ``size`` into ``folder``; return the manifest path."""
    folder = Path(folder)
    mesh_path = Path(mesh_path).resolve()
    mesh = load_mesh(mesh_path)
    disc = ff.face_disc(mesh)
    waves = ff.pore_waves(np.random.default_rng(ff.FIXTURE_SEED))
    fx = ff.FaceFixture(
        mesh,
        disc,
        np.zeros((0, 0, 2), np.float32),
        np.zeros((2, 0, 0, 2), np.float32),
        np.zeros((8, 0, 0), np.float32),
    )  # names, regions and expressions only: the maps are written below, band by band
    names = ["base_normal.png", *(f"wrinkle_{s}.png" for s in fx.state_names)]
    names += [f"masks/{r.name}.png" for r in fx.regions]
    (folder / "masks").mkdir(parents=True, exist_ok=True)
    with _writers(folder, names, size) as out:
        for r0 in range(0, size, BAND):
            rows = (r0, min(r0 + BAND, size))
            base, wrinkles, masks = ff.fixture_rows(size, disc, waves, rows)
            out[0].add(quantize(model.pd_to_normal(base) * 0.5 + 0.5, 16))
            for k in range(len(fx.state_names)):
                n = model.pd_to_normal(base + wrinkles[k])
                out[1 + k].add(quantize(n * 0.5 + 0.5, 16))
            for j, m in enumerate(masks):
                out[1 + len(fx.state_names) + j].add(quantize(m, 8))
    head = f"# wrinklepipe film-scale head case v{CASE_VERSION} at {size}^2 (generated)\n"
    text = head + ff.manifest_text(fx, mesh_path).split("\n", 1)[1]
    manifest = folder / "manifest.toml"
    write_bytes(manifest, text.replace('name = "cesium_face"', 'name = "head"').encode("utf-8"))
    return manifest


@contextlib.contextmanager
def _writers(folder: Path, names: list[str], size: int) -> Iterator[list[PngRows]]:
    """One :class:`PngRows` per file (masks: 8-bit grey; maps: 16-bit RGB), each writing into
    its atomic temporary path; all published together at the end, none on an error."""
    with contextlib.ExitStack() as stack:
        out = []
        for name in names:
            c, depth = (1, 8) if name.startswith("masks/") else (3, 16)
            f = stack.enter_context(open(stack.enter_context(temp_path(folder / name)), "wb"))
            out.append(PngRows(f, size, size, c, depth, DEFAULT_PNG_LEVEL, linear=True))
        yield out
        for png in out:
            png.close()


def head_case_dir(size: int, mesh_path: str | Path = MESH) -> Path:
    """The cached case at ``size`` (generated on first use into ``$WRINKLEPIPE_CACHE``);
    returns its manifest path."""
    mesh_path = Path(mesh_path).resolve()
    key = hashlib.sha256(str(mesh_path).encode("utf-8")).hexdigest()[:8]
    target = cache_root() / f"head-case-v{CASE_VERSION}-{size}-{key}"
    manifest = target / "manifest.toml"
    if not manifest.is_file():
        with staged_folder(target, force=True) as tmp:
            write_head_case(tmp, size, mesh_path)
    return manifest
