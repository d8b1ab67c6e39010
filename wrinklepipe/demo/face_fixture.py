"""The fidelity fixture: analytic wrinkles on the face of a real mesh, with exact truth.

Built from Cesium's *CesiumMan* (Khronos glTF sample, ``../shared/data``): an artist's UV layout
(torso, limbs, the head's face plate and back as two discs) where the face takes about 7 % of
the UV square. Everything else is generated, deterministically:

- a base height of pore-scale detail over the whole map (plane waves of 4 to 10 texels at 1024)
  and a small scar on the face;
- two wrinkle heights inside the face disc: **stretch** (forehead lines) and **compress**
  (glabella lines, crow's feet, nose lines, nasolabial creases), creases about 2 texels wide at
  1024, covering about 3 % of the UV area, as on a scanned head;
- 8 regions with ``_L`` / ``_R`` names (the character's sides: its left is +u on the face),
  8-bit soft masks at full resolution;
- 6 expressions.

Heights are :class:`wrinklepipe.demo.fields.Field` values, so their slopes are exact: the true
normal of the face under any weights is ``normalize(p_base + sum_k a_k p_k, 1)`` with ``a_k`` the
activations of the masks (:meth:`FaceFixture.truth`), independent of anything the pipeline does.

``write_fixture_source(folder, mesh)`` writes it as an artist would hand it over (16-bit PNG
maps, 8-bit masks, a manifest with every choice on ``auto``; the mesh is referenced where it
lies, never copied); :func:`fixture_source_dir` caches that.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wrinklepipe import model
from wrinklepipe.asset import Mesh, Region, WrinkleAsset
from wrinklepipe.atomic import staged_folder, write_bytes
from wrinklepipe.demo import fields as F
from wrinklepipe.demo.source import cache_root
from wrinklepipe.errors import input_error
from wrinklepipe.io.images import write_image
from wrinklepipe.options import BudgetOptions
from wrinklepipe.readers.meshes import load_mesh

FIXTURE_VERSION = 2
FIXTURE_SEED = 15
#: Where the mesh lives under ``../shared/data``.
MESH_RELPATH = "gltf-samples/CesiumMan/glTF-Binary/CesiumMan.glb"
STATE_NAMES: tuple[str, ...] = ("stretch", "compress")

#: (region name, side, state it drives)
REGIONS: tuple[tuple[str, str, str], ...] = (
    ("forehead_L", "left", "stretch"),
    ("forehead_R", "right", "stretch"),
    ("glabella", "center", "compress"),
    ("crow_L", "left", "compress"),
    ("crow_R", "right", "compress"),
    ("nose", "center", "compress"),
    ("nasolabial_L", "left", "compress"),
    ("nasolabial_R", "right", "compress"),
)

EXPRESSIONS: dict[str, dict[str, float]] = {
    "surprise": {"forehead_L": 1.0, "forehead_R": 1.0},
    "anger": {"glabella": 1.0, "nose": 0.6},
    "joy": {"crow_L": 1.0, "crow_R": 1.0, "nasolabial_L": 0.8, "nasolabial_R": 0.8},
    "disgust": {"nose": 1.0, "nasolabial_L": 0.5, "nasolabial_R": 0.5, "glabella": 0.4},
    "wink_L": {"crow_L": 1.0},
    "sneer_R": {"nasolabial_R": 1.0, "nose": 0.3},
}


@dataclass(frozen=True)
class FaceDisc:
    """The face plate's chart in UV: centre and radii (u, v)."""

    cu: float
    cv: float
    ru: float
    rv: float


@dataclass
class FaceFixture:
    """Exact slopes, masks, regions, expressions and the real mesh."""

    mesh: Mesh
    disc: FaceDisc
    base_slopes: np.ndarray  # [H, W, 2] float32
    wrinkle_slopes: np.ndarray  # [K, H, W, 2] float32 (the wrinkle alone)
    masks: np.ndarray  # [R, H, W] float32, 8-bit values (k / 255)
    state_names: tuple[str, ...] = STATE_NAMES
    regions: tuple[Region, ...] = field(
        default_factory=lambda: tuple(Region(n, s, (k,)) for n, s, k in REGIONS)
    )
    expressions: dict[str, dict[str, float]] = field(
        default_factory=lambda: {e: dict(r) for e, r in EXPRESSIONS.items()}
    )

    @property
    def size(self) -> int:
        return int(self.base_slopes.shape[0])

    @property
    def base_normal(self) -> np.ndarray:
        return model.pd_to_normal(self.base_slopes)

    def wrinkled_normal(self, k: int) -> np.ndarray:
        """The face in state ``k`` at full activation (what an artist's state map holds)."""
        return model.pd_to_normal(self.base_slopes + self.wrinkle_slopes[k])

    def asset(self) -> WrinkleAsset:
        states = np.stack([self.wrinkled_normal(k) for k in range(len(self.state_names))])
        return WrinkleAsset(
            name="cesium_face",
            base=self.base_normal,
            states=states,
            state_names=self.state_names,
            masks=self.masks,
            regions=self.regions,
            expressions=self.expressions,
            mesh=self.mesh,
            budget=BudgetOptions.from_json(BUDGET),
            provenance={"generator": "wrinklepipe.demo.face_fixture", "seed": FIXTURE_SEED},
        )

    def weights(self, expression: str) -> np.ndarray:
        """``[R, K]`` weights of one expression at full amount."""
        return self.asset().expression_weights({expression: 1.0})

    def truth(self, weights: np.ndarray, policy: str = "clamp01") -> np.ndarray:
        """The exact normal ``[H, W, 3]`` of the face under region weights ``[R, K]``."""
        act = model.activations(self.masks, weights, policy)
        d = self.base_slopes + np.einsum("k...,k...c->...c", act, self.wrinkle_slopes)
        return model.pd_to_normal(d)

    def wrinkle_fraction(self, deg: float = 0.5) -> float:
        """Fraction of the UV square where some wrinkle tilts the normal by more than ``deg``."""
        tilt = np.degrees(np.arctan(np.linalg.norm(self.wrinkle_slopes, axis=-1))).max(axis=0)
        return float((tilt > deg).mean())


#: The fixture's error budget: degrees, inside each pose's active region.
BUDGET: dict[str, float] = {
    "max_mean_deg": 0.5,
    "max_p99_deg": 1.0,
    "compressed_max_mean_deg": 1.0,
    "compressed_max_p99_deg": 2.5,
}


def face_disc(mesh: Mesh) -> FaceDisc:
    """The UV disc of CesiumMan's face plate: the head vertices (top quarter of the figure)
    whose normals face +X (the way the figure looks)."""
    p = np.asarray(mesh.positions, np.float64)
    n = np.asarray(mesh.normals, np.float64)
    up = int(np.argmax(p.max(axis=0) - p.min(axis=0)))  # the figure's height axis
    top = p[:, up] > p[:, up].min() + 0.8 * np.ptp(p[:, up])
    sel = top & (n[:, 0] > 0.99)
    if sel.sum() < 50:
        raise input_error(mesh.name, "no face plate found (expected CesiumMan's head)")
    uv = np.asarray(mesh.uvs, np.float64)[sel]
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    c, r = (lo + hi) / 2.0, (hi - lo) / 2.0
    return FaceDisc(float(c[0]), float(c[1]), float(r[0]), float(r[1]))


# ------------------------------------------------------------------------------------------------
# heights (UV units; slopes are dimensionless and resolution independent)


def _pores(size: int, rng: np.random.Generator) -> F.Field:
    """Plane waves of 6 to 14 texels (at 1024) in random directions: pore-scale relief."""
    return pores_rows(size, pore_waves(rng))


def pore_waves(rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    """The pore waves' wave numbers, directions, phases and amplitudes (40 plane waves)."""
    n = 40
    k = 2.0 * np.pi / (rng.uniform(6.0, 14.0, n) / 1024.0)
    theta = rng.uniform(0.0, np.pi, n)
    phase = rng.uniform(0.0, 2.0 * np.pi, n)
    amp = 0.012 / k  # slope amplitude 0.012 per wave: a few degrees in total
    return k, theta, phase, amp


def pores_rows(
    size: int, waves: tuple[np.ndarray, ...], rows: tuple[int, int] | None = None
) -> F.Field:
    """The pore relief of :func:`pore_waves` on texel rows ``rows`` (half-open; all rows by
    default) of a ``size`` x ``size`` map.

    ``sin(a(u) + b(v)) = sin a cos b + cos a sin b`` makes every wave separable, so the sum
    over waves is two small matrix products (no trigonometry per texel).
    """
    k, theta, phase, amp = waves
    r0, r1 = rows or (0, size)
    c = (np.arange(size, dtype=np.float64) + 0.5) / size
    a = np.outer(k * np.cos(theta), c) + phase[:, None]  # [n, W] along u
    b = np.outer(k * np.sin(theta), c[r0:r1])  # [n, H] along v
    sa, ca, sb, cb = np.sin(a), np.cos(a), np.sin(b), np.cos(b)

    def outer(x: np.ndarray, y: np.ndarray, w: np.ndarray) -> np.ndarray:  # sum_i w_i y_i[v] x_i[u]
        return (y * w[:, None]).T @ x

    h = outer(sa, cb, amp) + outer(ca, sb, amp)
    gu, gv = amp * k * np.cos(theta), amp * k * np.sin(theta)  # d(arg)/du, d(arg)/dv
    du = outer(ca, cb, gu) - outer(sa, sb, gu)  # amp k_u cos(a + b)
    dv = outer(ca, cb, gv) - outer(sa, sb, gv)
    return F.Field(h, du, dv)


def _crease_lines(q: F.Field, period: float, n: int) -> F.Field:
    """Periodic creases across ``q``: ``((1 + cos(2 pi q / period)) / 2) ** n``."""
    return ((1.0 + F.cos(q * (2.0 * np.pi / period))) * 0.5).pow(n)


def face_window(size: int, disc: FaceDisc) -> tuple[tuple[int, int], tuple[int, int]]:
    """Texel rows and columns (half-open) that hold the face disc, with a margin."""
    r = (
        max(int((disc.cv - 1.05 * disc.rv) * size), 0),
        min(int((disc.cv + 1.05 * disc.rv) * size) + 2, size),
    )
    c = (
        max(int((disc.cu - 1.05 * disc.ru) * size), 0),
        min(int((disc.cu + 1.05 * disc.ru) * size) + 2, size),
    )
    return r, c


def _face_heights(u: F.Field, v: F.Field, disc: FaceDisc) -> tuple[F.Field, F.Field, F.Field]:
    """Scar, stretch and compress heights at the points ``u``, ``v`` (all 0 off the face)."""
    fx = (u - disc.cu) / disc.ru  # across the face, the character's left positive
    fy = (v - disc.cv) / disc.rv  # down the face
    # a scar on the character's right cheek: a raised ridge
    scar = F.gaussian(fy - 0.35 - 0.4 * (fx + 0.45), 0.012) * F.box(fx, -0.6, -0.3, 0.04)
    scar = scar * 0.0008
    depth = 0.0045  # UV units: creases 5 to 8 texels wide at 1024 tilt the normal ~25 deg
    # stretch: forehead lines, slightly curved, deeper in the middle
    fore_env = F.box(fy, -0.84, -0.48, 0.12) * F.box(fx, -0.46, 0.46, 0.14)
    lines = _crease_lines(fy - fx * fx * 0.06, 0.18, 1)
    stretch = -lines * fore_env * depth
    # compress: glabella (two vertical lines), crow's feet, nose lines, nasolabial creases
    glab = F.const(u, 0.0)
    for x0 in (-0.09, 0.09):
        glab = glab + F.gaussian(fx - x0 - (fy + 0.3) * 0.2, 0.04)
    glab = glab * F.box(fy, -0.40, -0.20, 0.1)
    crow = F.const(u, 0.0)  # crow's feet: five lines fanning out from each outer eye corner
    for side in (-1.0, 1.0):
        dx, dy = (fx - side * 0.60) * side, fy + 0.22
        for th in (-0.7, -0.35, 0.0, 0.35, 0.7):
            along = dx * np.cos(th) + dy * np.sin(th)
            across = dy * np.cos(th) - dx * np.sin(th)
            ray = F.smoothstep(0.05, 0.12, along) * (1.0 - F.smoothstep(0.15, 0.25, along))
            crow = crow + F.gaussian(across, 0.03) * ray
    nose = _crease_lines(fy + 0.02, 0.15, 1) * F.box(fy, -0.12, 0.04, 0.08)
    nose = nose * F.box(fx, -0.06, 0.06, 0.08)
    naso = F.const(u, 0.0)
    for side in (-1.0, 1.0):
        t = fy - 0.1
        line = fx - (0.24 + t * 0.12 + t * t * 0.35) * side
        naso = naso + F.gaussian(line, 0.045) * F.box(fy, 0.2, 0.48, 0.12)
    compress = -(glab * 1.1 + crow * 0.8 + nose * 0.9 + naso) * depth
    return scar, stretch, compress


def _slopes(size: int, disc: FaceDisc, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Base slopes ``[H, W, 2]`` and wrinkle slopes ``[K, H, W, 2]``, exact."""
    base = _pores(size, rng).slopes
    rows, cols = face_window(size, disc)
    u, v = F.coords(size, rows, cols)
    scar, stretch, compress = _face_heights(u, v, disc)
    win = (slice(*rows), slice(*cols))
    base[win] += scar.slopes
    wrinkles = np.zeros((2, size, size, 2), np.float32)
    wrinkles[(0, *win)] = stretch.slopes
    wrinkles[(1, *win)] = compress.slopes
    return base, wrinkles


def fixture_rows(
    size: int, disc: FaceDisc, waves: tuple[np.ndarray, ...], rows: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Texel rows ``rows`` (half-open) of the fixture at ``size``: base slopes ``[n, W, 2]``,
    wrinkle slopes ``[K, n, W, 2]`` and masks ``[R, n, W]``, so a large fixture is made band
    by band (:mod:`wrinklepipe.bench.head_case`). Texel for texel the values of the whole
    fixture, up to the pore sum's matrix products (summed in another order per band)."""
    r0, r1 = rows
    base = pores_rows(size, waves, rows).slopes
    wrinkles = np.zeros((2, r1 - r0, size, 2), np.float32)
    (f0, f1), cols = face_window(size, disc)
    a, b = max(r0, f0), min(r1, f1)
    if a < b:
        u, v = F.coords(size, (a, b), cols)
        scar, stretch, compress = _face_heights(u, v, disc)
        win = (slice(a - r0, b - r0), slice(*cols))
        base[win] += scar.slopes
        wrinkles[(0, *win)] = stretch.slopes
        wrinkles[(1, *win)] = compress.slopes
    return base, wrinkles, _masks(size, disc, rows)


def _masks(size: int, disc: FaceDisc, rows: tuple[int, int] | None = None) -> np.ndarray:
    """The 8 regions' masks ``[R, H, W]`` (8-bit values; on texel rows ``rows`` only when
    given)."""
    u, v = F.coords(size, rows)
    fx = (u.f - disc.cu) / disc.ru
    fy = (v.f - disc.cv) / disc.rv

    def box(x: np.ndarray, lo: float, hi: float, soft: float) -> np.ndarray:
        t0 = np.clip((x - lo + soft) / (2 * soft), 0, 1)
        t1 = np.clip((x - hi + soft) / (2 * soft), 0, 1)
        return t0 * t0 * (3 - 2 * t0) * (1 - t1 * t1 * (3 - 2 * t1))

    left = np.clip((fx + 0.03) / 0.06, 0.0, 1.0)
    left = left * left * (3 - 2 * left)
    fore = box(fy, -0.94, -0.40, 0.06) * box(fx, -0.60, 0.60, 0.08)
    glab = box(fy, -0.46, -0.14, 0.05) * box(fx, -0.22, 0.22, 0.05)
    r2 = lambda side: np.hypot(fx - side * 0.60, fy + 0.22)  # noqa: E731
    crow = [1.0 - np.clip((r2(s) - 0.22) / 0.06, 0.0, 1.0) for s in (1.0, -1.0)]
    crow = [c * c * (3 - 2 * c) * (s * fx > 0.5) for c, s in zip(crow, (1.0, -1.0))]
    nose = box(fy, -0.20, 0.12, 0.04) * box(fx, -0.16, 0.16, 0.04)
    naso = box(fy, 0.10, 0.60, 0.06)
    naso_l = naso * box(fx, 0.14, 0.52, 0.06)
    naso_r = naso * box(fx, -0.52, -0.14, 0.06)
    m = np.stack(
        [fore * left, fore * (1 - left), glab, crow[0], crow[1], nose, naso_l, naso_r]
    ).astype(np.float64)
    return (np.rint(np.clip(m, 0.0, 1.0) * 255.0) / 255.0).astype(np.float32)


def build_fixture(mesh_path: str | Path, size: int = 1024) -> FaceFixture:
    """The fixture at ``size`` x ``size`` on the mesh at ``mesh_path`` (CesiumMan.glb)."""
    mesh = load_mesh(mesh_path)
    disc = face_disc(mesh)
    rng = np.random.default_rng(FIXTURE_SEED)
    base, wrinkles = _slopes(size, disc, rng)
    return FaceFixture(
        mesh=mesh,
        disc=disc,
        base_slopes=base,
        wrinkle_slopes=wrinkles,
        masks=_masks(size, disc),
    )


# ------------------------------------------------------------------------------------------------
# as files


def manifest_text(fx: FaceFixture, mesh_path: Path, sides: bool = True) -> str:
    """The fixture's manifest: every choice ``auto``; the budget is the fixture's.

    ``sides=False`` leaves ``side`` out of every region (the names still end in _L / _R).
    """
    lines = [
        f"# wrinklepipe fidelity fixture (generated, v{FIXTURE_VERSION}, seed {FIXTURE_SEED})",
        'schema = "wrinklepipe/manifest@1"',
        'name = "cesium_face"',
        f"mesh = {_toml_str(mesh_path.as_posix())}",
        'base = "base_normal.png"',
        'convention = "opengl"',
        'encoding = "pd"',
        'policy = "clamp01"',
        'pd_scale = "auto"',
        "states_include_base = true",
        "",
        "[resolution]",
        'wrinkle = "auto"',
        'mask = "auto"',
        "",
        "[budget]",
        *(f"{k} = {v}" for k, v in BUDGET.items()),
        "",
    ]
    for name in fx.state_names:
        lines += ["[[states]]", f'name = "{name}"', f'map = "wrinkle_{name}.png"', ""]
    for r in fx.regions:
        lines += ["[[regions]]", f'name = "{r.name}"', f'mask = "masks/{r.name}.png"']
        if sides:
            lines.append(f'side = "{r.side}"')
        lines += [f"states = [{', '.join(_toml_str(s) for s in r.states)}]", ""]
    for e, row in fx.expressions.items():
        lines.append(f"[expressions.{e}]")
        lines += [f"{r} = {w}" for r, w in row.items()]
        lines.append("")
    return "\n".join(lines)


def _toml_str(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def write_fixture_source(
    folder: str | Path, mesh_path: str | Path, size: int = 1024, sides: bool = True
) -> Path:
    """Write the fixture's source files into ``folder``; return the manifest path."""

    mesh_path = Path(mesh_path).resolve()
    return write_fixture_files(folder, build_fixture(mesh_path, size), mesh_path, sides)


def write_fixture_files(
    folder: str | Path, fx: FaceFixture, mesh_path: str | Path, sides: bool = True
) -> Path:
    """Write the built fixture ``fx`` (on the mesh at ``mesh_path``) as source files into
    ``folder``; return the manifest path. For a caller that also needs ``fx`` itself."""

    folder = Path(folder)
    mesh_path = Path(mesh_path).resolve()
    folder.mkdir(parents=True, exist_ok=True)
    write_image(folder / "base_normal.png", fx.base_normal * 0.5 + 0.5, bits=16)
    for k, name in enumerate(fx.state_names):
        write_image(folder / f"wrinkle_{name}.png", fx.wrinkled_normal(k) * 0.5 + 0.5, bits=16)
    for r, mask in zip(fx.regions, fx.masks):
        write_image(folder / "masks" / f"{r.name}.png", mask, bits=8)
    manifest = folder / "manifest.toml"
    write_bytes(manifest, manifest_text(fx, mesh_path, sides).encode("utf-8"))
    return manifest


def fixture_source_dir(mesh_path: str | Path, size: int = 1024) -> Path:
    """The cached fixture source (generated on first use); returns its manifest path."""

    mesh_path = Path(mesh_path).resolve()
    key = hashlib.sha256(str(mesh_path).encode("utf-8")).hexdigest()[:8]
    target = cache_root() / f"face-fixture-v{FIXTURE_VERSION}-{size}-{key}"
    manifest = target / "manifest.toml"
    if manifest.is_file():
        return manifest
    with staged_folder(target, force=True) as tmp:
        write_fixture_source(tmp, mesh_path, size)
    return manifest
