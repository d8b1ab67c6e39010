"""``wrinklepipe bench normals``: the BC5 encoder against the exhaustive search and the PyPI
encoders, and the whole 4096^2 map -> PD -> BC5 -> decode -> error path against the encoder.

Quality, in the same run, every encoder on the same 256^2 crops (32^2 of the 256^2 demo in
the quick run): the demo's 1024^2 base (pores and the scar), and the busiest window of
DamagedHelmet's normal map from ``../shared/data`` when it is present. Decoded by
texture2ddecoder; degrees against the float source (demo) or the 8-bit map itself (the real
map's source is 8-bit; z rebuilt from its x, y). Encoders: ours
(:func:`wrinklepipe.normals.bc4.encode_bc5`), the exhaustive endpoint search
(:func:`~wrinklepipe.normals.bc4.reference_bc4`), etcpak, quicktex, ispc_texcomp; each row's
time is its median encode time and its note the mean / p99. BC1, BC3nm and BC7 normal maps
(z in B where the format has it) are compared per library the same way on the demo crop;
``extra["formats"]`` holds every number, ``extra["choice"]`` the encoder each format uses.
NormalTangentTest's busiest window is a quality row too (with ``../shared``).

Speed: the fused path (:func:`wrinklepipe.normals.pd_fused.pd_compress_check`) on a 4096^2 PD
map as a ratio to the bare BC5 encoder on the same packed texels (the baseline), and the bare
encoder's Mpix per CPU second (all threads' CPU time: what one core does, whatever the load).
Repeats are interleaved so load from other processes hits all rows alike; medians are reported.
"""

from __future__ import annotations

import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import etcpak
import ispc_texcomp
import numpy as np
import OpenImageIO as oiio
import pygltflib
import quicktex
import quicktex.s3tc.bc1 as quicktex_bc1
import quicktex.s3tc.bc3 as quicktex_bc3
import quicktex.s3tc.bc5 as quicktex_bc5
import texture2ddecoder

from wrinklepipe import codec
from wrinklepipe.bench import BenchResult, BenchRow, benchmark
from wrinklepipe.demo import character
from wrinklepipe.io.images import write_image
from wrinklepipe.metrics import DECIMALS, angle_deg, weighted_stats
from wrinklepipe.model import height_to_normal
from wrinklepipe.normals import bc4, pd_fused
from wrinklepipe.normals import compress as cmp
from wrinklepipe.normals import encode as enc
from wrinklepipe.normals._chunks import threads as _threads
from wrinklepipe.normals.read import ReadOptions, read_normal_map
from wrinklepipe.normals.resample import resize
from wrinklepipe.paths import ROOT

SIZE = 4096
#: The BC5 encoder before its coarse-to-fine hard-block search (a row, not a limit).
BEFORE = "BC5 encoder before (whole hard window; same blocks otherwise)"
QUICK_SIZE = 256  # quick: a smoke run (the test suite's); fixed costs dominate
SAMPLES = ROOT.parent / "shared" / "data" / "gltf-samples"
#: The real normal maps of the quality rows (glTF samples; skipped when ../shared is absent).
REAL_MAPS = ("DamagedHelmet", "NormalTangentTest")
#: The one-core throughput row (CPU seconds of the whole process: every thread's work).
ONE_CORE = "bare BC5 encoder, Mpix per CPU second (one core)"
#: The encoder each block format uses (what :func:`compress.encode_bc` calls), and why.
CHOICE = {
    "bc5": "wrinklepipe.normals.bc4 (lowest mean and p99 after the exhaustive search)",
    "bc3nm": "alpha (x): wrinklepipe.normals.bc4; colour (y): quicktex level 5",
    "bc1": "quicktex level 5 (lowest error; ispc_texcomp and etcpak trail)",
    "bc7": "ispc_texcomp 'basic' (lowest error; etcpak's bc7enc trails)",
}


def bench_map(size: int) -> np.ndarray:
    """A deterministic wrinkle-like normal map [size, size, 3] (float32, unit, +Y).

    The demo's 512^2 wrinkle and pore heights magnified to ``size`` (so the slope statistics
    match a real wrinkle map: folds, pores, flat areas), plus fine seeded noise.
    """
    base = min(size, 512)
    d = character.generate(base)
    h = (d.base_height + d.wrinkle_heights[1]).astype(np.float32)
    if size != base:
        h = resize(h, size, "blackman-harris") * np.float32(size / base)
    rng = np.random.default_rng(4096)
    h += rng.standard_normal(h.shape).astype(np.float32) * np.float32(0.05)
    return height_to_normal(h).astype(np.float32)


def _helmet_texels(tmp: Path, name: str = "DamagedHelmet") -> np.ndarray | None:
    """A glTF sample's normal texture (8-bit RGB; DamagedHelmet's unless ``name`` says which),
    or None without ../shared."""
    glb = SAMPLES / name / "glTF-Binary" / f"{name}.glb"
    if not glb.exists():
        return None
    g = pygltflib.GLTF2().load(str(glb))
    mat = next(m for m in g.materials if m.normalTexture is not None)
    img = g.images[g.textures[mat.normalTexture.index].source]
    bv = g.bufferViews[img.bufferView]
    start = bv.byteOffset or 0
    path = tmp / (f"{name}_normal.jpg" if "jpeg" in (img.mimeType or "") else f"{name}_normal.png")
    path.write_bytes(g.binary_blob()[start : start + bv.byteLength])
    return np.asarray(oiio.ImageBuf(str(path)).get_pixels(oiio.UINT8))[..., :3]


def _busiest(texels: np.ndarray, size: int) -> np.ndarray:
    h, w = texels.shape[:2]
    best, where = -1.0, (0, 0)
    for y in range(0, h - size + 1, size // 2):
        for x in range(0, w - size + 1, size // 2):
            v = float(texels[y : y + size, x : x + size, :2].astype(np.float32).std())
            if v > best:
                best, where = v, (y, x)
    return texels[where[0] : where[0] + size, where[1] : where[1] + size]


def _stats(n: np.ndarray, ref: np.ndarray) -> dict[str, float]:
    s = weighted_stats(angle_deg(n, ref))
    return {"mean_deg": round(s.mean, DECIMALS), "p99_deg": round(s.p99, DECIMALS)}


def _rgba(q: np.ndarray) -> np.ndarray:
    h, w, c = q.shape
    out = np.zeros((h, w, 4), np.uint8)
    out[..., :c] = q
    out[..., 3] = 255
    return out


def _bc5_encoders(targets: np.ndarray) -> dict[str, Callable[[], bytes]]:
    h, w = targets.shape[:2]
    q = np.clip(np.floor(targets + 0.5), 0, 255).astype(np.uint8)
    rgba = _rgba(q)
    rg = np.ascontiguousarray(q)

    def exhaustive() -> bytes:
        x, y = bc4.reference_bc4(targets[..., 0]), bc4.reference_bc4(targets[..., 1])
        return np.concatenate([x, y], axis=1).tobytes()

    def quick() -> bytes:
        tex = quicktex.RawTexture.frombytes(rgba.tobytes(), w, h)
        return bytes(quicktex_bc5.BC5Encoder(0, 1).encode(tex).tobytes())

    return {
        "ours": lambda: bc4.encode_bc5(targets[..., 0], targets[..., 1]),
        "ours (before: whole hard window)": lambda: bc4.encode_bc5(
            targets[..., 0], targets[..., 1], hard_step=1
        ),
        "exhaustive": exhaustive,
        "etcpak": lambda: etcpak.compress_bc5(rgba, w, h),
        "quicktex": quick,
        "ispc_texcomp": lambda: ispc_texcomp.compress_blocks_bc5(
            ispc_texcomp.RGBASurface(rg.tobytes(), w, h, w * 2)
        ),
    }


def _decode(fmt: str, data: bytes, h: int, w: int) -> np.ndarray:
    fn = getattr(texture2ddecoder, f"decode_{fmt}")
    return np.frombuffer(fn(data, w, h), np.uint8).reshape(h, w, 4)[..., [2, 1, 0, 3]]


def _timed(fn: Callable[[], bytes], repeat: int) -> tuple[bytes, float]:
    times, data = [], b""
    for _ in range(repeat):
        t0 = time.perf_counter()
        data = fn()
        times.append(time.perf_counter() - t0)
    return data, float(np.median(times))


def _bc5_quality(
    res: BenchResult, crops: dict[str, tuple[np.ndarray, np.ndarray]], repeat: int = 3
) -> None:
    out: dict[str, dict[str, dict[str, float]]] = {}
    for crop, (targets, ref) in crops.items():
        h, w = targets.shape[:2]
        out[crop] = {}
        for name, fn in _bc5_encoders(targets).items():
            data, sec = _timed(fn, 1 if name == "exhaustive" else repeat)
            dec = _decode("bc5", data, h, w)
            s = _stats(codec.decode("full", dec[..., :2], "rg"), ref) | {"seconds": round(sec, 4)}
            out[crop][name] = s
            res.rows.append(
                BenchRow(
                    step=f"BC5 {crop}: {name}",
                    median_s=sec,
                    mpix_per_s=h * w / 1e6 / sec,
                    note=f"mean {s['mean_deg']:.4f} p99 {s['p99_deg']:.4f} deg",
                )
            )
        ours, ex = out[crop]["ours"], out[crop]["exhaustive"]
        out[crop]["ours_vs_exhaustive"] = {
            "mean_ratio": round(ours["mean_deg"] / max(ex["mean_deg"], 1e-12), 4),
            "p99_ratio": round(ours["p99_deg"] / max(ex["p99_deg"], 1e-12), 4),
        }
    res.extra["bc5"] = out


def _format_quality(res: BenchResult, q: np.ndarray, ref: np.ndarray) -> None:
    """BC1 / BC3nm / BC7 normal maps (the codec's layouts) per library, on the demo crop."""
    h, w = q.shape[:2]
    rgb = _rgba(q)  # x, y, z in R, G, B
    nm = np.zeros((h, w, 4), np.uint8)
    nm[..., 0], nm[..., 1], nm[..., 3] = 255, q[..., 1], q[..., 0]  # DXT5nm
    surf = ispc_texcomp.RGBASurface
    qt = quicktex.RawTexture.frombytes

    def bc3_ours() -> bytes:
        return cmp.encode_bc(nm, "bc3nm")

    cases: dict[str, dict[str, Callable[[], bytes]]] = {
        "bc1": {
            "etcpak": lambda: etcpak.compress_bc1(rgb, w, h),
            "quicktex": lambda: bytes(
                quicktex_bc1.BC1Encoder(cmp.QUICKTEX_LEVEL)
                .encode(qt(rgb.tobytes(), w, h))
                .tobytes()
            ),
            "ispc_texcomp": lambda: ispc_texcomp.compress_blocks_bc1(
                surf(rgb.tobytes(), w, h, w * 4)
            ),
            "ours (quicktex levels 5 and 0, per block)": lambda: cmp.encode_bc(rgb, "bc1"),
        },
        "bc3": {
            "etcpak": lambda: etcpak.compress_bc3(nm, w, h),
            "quicktex": lambda: bytes(
                quicktex_bc3.BC3Encoder(cmp.QUICKTEX_LEVEL).encode(qt(nm.tobytes(), w, h)).tobytes()
            ),
            "ispc_texcomp": lambda: ispc_texcomp.compress_blocks_bc3(
                surf(nm.tobytes(), w, h, w * 4)
            ),
            "ours (bc4 alpha + quicktex colour)": bc3_ours,
        },
        "bc7": {
            "etcpak": lambda: etcpak.compress_bc7(rgb, w, h, None),
            "ispc_texcomp": lambda: ispc_texcomp.compress_blocks_bc7(
                surf(rgb.tobytes(), w, h, w * 4),
                ispc_texcomp.BC7EncSettings.from_profile(cmp.ISPC_BC7_PROFILE),
            ),
        },
    }
    out: dict[str, dict[str, dict[str, float]]] = {}
    for fmt, encs in cases.items():
        out[fmt] = {}
        for name, fn in encs.items():
            data, sec = _timed(fn, 1)
            dec = _decode(fmt, data, h, w)
            if fmt == "bc3":
                n = codec.decode("full", dec, "ag")
            else:
                n = codec.decode("full", dec[..., :3], "rgb")
            s = _stats(n, ref) | {"seconds": round(sec, 4)}
            out[fmt][name] = s
            res.rows.append(
                BenchRow(
                    step=f"{'BC3nm' if fmt == 'bc3' else fmt.upper()} demo: {name}",
                    median_s=sec,
                    mpix_per_s=h * w / 1e6 / sec,
                    note=f"mean {s['mean_deg']:.3f} p99 {s['p99_deg']:.3f} deg",
                )
            )
    res.extra["formats"] = out
    res.extra["choice"] = dict(CHOICE)


@benchmark("normals", "BC5 vs exhaustive/etcpak/quicktex/ispc on 256^2 crops; 4096^2 fused path")
def bench_normals(quick: bool) -> BenchResult:
    size = QUICK_SIZE if quick else SIZE
    crop = 32 if quick else 256
    repeat = 1 if quick else 3  # quick: a smoke run (the test suite's), each step once
    mp = size * size / 1e6
    res = BenchResult(
        name="normals",
        description=f"BC5 quality on {crop}^2 crops; {size}^2 PD -> BC5 -> decode -> error",
        baseline="bare BC5 encoder (normals.bc4.encode_bc5)",
        limits={} if quick else {"whole (fused, no read)": 1.5},
    )
    with tempfile.TemporaryDirectory() as tmp:
        # --- quality on crops
        demo = character.generate(256 if quick else 1024).base_normal.astype(np.float32)
        y0 = 96 if quick else 384
        n = demo[y0 : y0 + crop, y0 : y0 + crop]
        crops = {"demo base": ((np.float32(127.5) + np.float32(127.5) * n[..., :2]), n)}
        for name in REAL_MAPS:
            texels = _helmet_texels(Path(tmp), name)
            if texels is not None:
                q = _busiest(texels, crop)
                crops[name] = (q[..., :2].astype(np.float32), codec.decode("full", q, "rg"))
        _bc5_quality(res, crops, repeat)
        q8, _ = codec.encode("full", n, "png8", channels=3)
        _format_quality(res, q8, n)

        # --- the fused path on the big map, against the bare encoder
        src = Path(tmp) / "normal16.png"
        write_image(src, bench_map(size) * np.float32(0.5) + np.float32(0.5), bits=16)
        opts = ReadOptions(convention="opengl", detect=False)
        normals = read_normal_map(src, opts).normals
        scale = enc.auto_pd_scale(normals)
        rgba, _ = pd_fused.pd_pack(normals, scale, "bc5")
        t = np.clip(normals[..., :2] / normals[..., 2:3] / np.float32(scale), -1, 1)
        targets = (np.float32(128) + np.float32(127) * t).astype(np.float32)
        base_name = "bare BC5 encoder (normals.bc4.encode_bc5)"
        steps = {
            base_name: lambda: bc4.encode_bc5(targets[..., 0], targets[..., 1]),
            "whole (fused, no read)": lambda: pd_fused.pd_compress_check(normals, scale, "bc5"),
            BEFORE: lambda: bc4.encode_bc5(targets[..., 0], targets[..., 1], hard_step=1),
        }
        times: dict[str, list[float]] = {k: [] for k in steps}
        cpu: list[float] = []
        last: dict[str, Any] = {}
        for _ in range(repeat):
            for name, fn in steps.items():
                t0, c0 = time.perf_counter(), time.process_time()
                last[name] = fn()
                times[name].append(time.perf_counter() - t0)
                if name == base_name:
                    cpu.append(time.process_time() - c0)
        check: pd_fused.PDCheck = last["whole (fused, no read)"]  # deterministic: the timed run's
        etc_t0 = time.perf_counter()
        etcpak.compress_bc5(rgba, size, size)
        etc_s = time.perf_counter() - etc_t0
    for name, ts in times.items():
        med = float(np.median(ts))
        res.rows.append(
            BenchRow(step=name, median_s=med, mpix_per_s=mp / med, note=f"best {min(ts):.3f} s")
        )
    cpu_med = float(np.median(cpu))
    res.rows.append(
        BenchRow(
            step=ONE_CORE,
            median_s=cpu_med,
            mpix_per_s=mp / cpu_med,
            note="CPU seconds of all threads: the work one core does",
        )
    )
    res.extra.update(
        {
            "threads": _threads(),
            "size": size,
            "scale": scale,
            "clipped": check.clipped,
            "error": check.error.to_json(),
            "bytes": len(check.data),
            "etcpak_bc5_seconds": round(etc_s, 4),
            "one_core_mpix_per_s": round(mp / cpu_med, 3),
            # the hard-block search made coarse-to-fine: the encoder before / now, same run
            "bc5_before_over_now": round(
                float(np.median(times[BEFORE]) / np.median(times[base_name])), 3
            ),
        }
    )
    return res.finish()
