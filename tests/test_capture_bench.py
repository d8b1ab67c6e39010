"""Smoke run of the capture benchmark in quick mode (the full run is ``wrinklepipe bench``)."""

from __future__ import annotations

from wrinklepipe.bench.capture import bench_capture


def test_capture_benchmark_quick():
    res = bench_capture(True)
    steps = [r.step for r in res.rows]
    assert steps[0] == res.baseline and "whole stage (4 methods)" in steps
    assert "orientation sfs" in steps  # the new method's time beside the others
    # and on a curved neutral, where the eikonal starts run
    assert {"sfs eikonal start, curved forehead", "orientation sfs, curved forehead"} <= set(steps)
    assert "orientation sfs + side-lit photo, curved forehead" in steps  # the side-lit solve
    assert all(r.median_s > 0 and r.ratio > 0 for r in res.rows)
    acc = res.extra["accuracy_deg"]
    assert set(acc) == {"gradient", "furrow", "integrable"}  # no neutral normals: no solve
    assert res.extra["default_method"] == "integrable"
    assert acc["integrable"]["tilt_mean"] < 0.5 * res.extra["flat_map_mean_deg"]
    cur = res.extra["curved_forehead"]
    # the neutral's normals are given and this forehead is nearly flat (N_z down to 0.99): auto
    # takes the solve only because it explains R far better than the prior (here the priors
    # find no crease at 64 px and stay flat)
    res_cur = {m: v["ratio_residual"] for m, v in cur["accuracy_deg"].items()}
    assert cur["default_method"] == "sfs"
    assert res_cur["sfs"] < 0.75 * res_cur["integrable"]
    assert set(cur["accuracy_deg"]) == set(acc) | {"sfs"}
