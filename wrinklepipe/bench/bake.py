"""Benchmark ``bake-states``: a 2048² wrinkle state baked from a 1M-triangle sculpt.

The low mesh is a UV sphere of 128 x 64 quads with MikkTSpace tangents, whose UV layout fills
the whole square (every texel baked: 16.8 M samples at 2 x 2 per texel, the worst case; a face
layout covers less); the sculpt a UV sphere of 1000 x 500 quads (998 000 triangles) displaced
along its normal by creases (no normals in the "file": the baker computes them, as for an OBJ
from a sculpting tool). Steps: the whole bake of one state
(:func:`wrinklepipe.geometry.bake.bake_normal_maps`: samples, frames, the BVH, the sculpt's
normals, rays, texels, padding), and as the baseline the rays alone (the same 16.8 M rays cast
by Embree, frames made beforehand). Limit: the bake within 60 s (the issue's minute), and its
CPU seconds are reported with the load average around the run.
"""

from __future__ import annotations

import os
import time
from dataclasses import replace

import numpy as np

from wrinklepipe.bench import BenchResult, BenchRow, benchmark
from wrinklepipe.geometry.bake import BakeOptions, HighMesh, RayScene, bake_normal_maps
from wrinklepipe.geometry.bake import sample_frames as frames
from wrinklepipe.geometry.primitives import uv_sphere
from wrinklepipe.geometry.tangents import mikktspace_tangents
from wrinklepipe.geometry.uv_samples import uv_samples


def _sculpt(n_lon: int, n_lat: int) -> HighMesh:
    """A UV sphere displaced by creases along v inside a band (no normals)."""
    m = uv_sphere(n_lon, n_lat)
    u = m.uvs[:, 0].astype(np.float64)
    v = m.uvs[:, 1].astype(np.float64)
    band = np.exp(-(((v - 0.5) / 0.2) ** 2)) * np.exp(-(((u - 0.5) / 0.3) ** 2))
    h = 0.002 * band * np.cos(2.0 * np.pi * 60.0 * v) ** 2
    p = m.positions.astype(np.float64) * (1.0 + h)[:, None]
    return HighMesh(p.astype(np.float32), m.indices, None, "sculpt")


@benchmark("bake-states", "bake a 2048^2 wrinkle state from a 1M-triangle sculpt (Embree rays)")
def bench_bake(quick: bool = False) -> BenchResult:
    size, (n_lon, n_lat) = (128, (100, 50)) if quick else (2048, (1000, 500))
    low = uv_sphere(128, 64)
    low = replace(
        low, tangents=mikktspace_tangents(low.positions, low.normals, low.uvs, low.indices)
    )
    sculpt = _sculpt(n_lon, n_lat)
    opts = BakeOptions(size=size, supersample=2)
    res = BenchResult(
        "bake-states",
        f"{size}^2 x 4 samples, sculpt {len(sculpt.indices)} triangles"
        + (" (quick)" if quick else ""),
        baseline="rays alone (Embree)",
    )
    load_before = os.getloadavg()
    # the baseline: the same rays, frames made beforehand
    samples = uv_samples(low.uvs, low.indices, size, opts.supersample)
    scene = RayScene(sculpt.positions, sculpt.indices)
    rays = [frames(low, samples, part) for part in samples.chunks()]
    d = 0.01
    t0 = time.perf_counter()
    for p, _, _, n in rays:
        scene.first_hit(p + d * n, -n, 2 * d)
    t_rays = time.perf_counter() - t0
    del rays, samples
    c0 = time.process_time()
    t0 = time.perf_counter()
    baked = bake_normal_maps(low, [sculpt], opts)
    t_bake = time.perf_counter() - t0
    cpu = time.process_time() - c0
    res.rows.append(BenchRow("rays alone (Embree)", t_rays))
    res.rows.append(BenchRow("bake 1 state", t_bake, mpix_per_s=size * size / 1e6 / t_bake))
    if not quick:
        res.limits_s = {"bake 1 state": 60.0}
    res.extra = {
        "size": size,
        "samples": baked.samples,
        "sculpt_triangles": int(len(sculpt.indices)),
        "missed_samples": baked.missed_samples[0],
        "ray_distance": baked.max_distance,
        "bake_cpu_s": round(cpu, 2),
        "cores": os.cpu_count(),
        "load_average_before": [round(x, 2) for x in load_before],
        "load_average_after": [round(x, 2) for x in os.getloadavg()],
    }
    return res.finish()
