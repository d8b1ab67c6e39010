"""Film scale: convert's report (issue 42). Its decode errors are made a state at a time over
the base resampled band by band from its texels, the numbers of the whole package decoded, bit
for bit (docs/scale.md, "Memory")."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from wrinklepipe import workset
from wrinklepipe.demo import demo_asset
from wrinklepipe.metrics import angle_deg, weighted_stats
from wrinklepipe.outputs.report import decode_errors
from wrinklepipe.pipeline import package as pp

U32 = np.uint32


def _asset(encoding: str, size: int, states: int):
    a = demo_asset(size, encoding=encoding, mesh_resolution=(12, 8))
    st = np.stack([pp.resize_normals_pd(s, states, states) for s in a.states])
    return replace(a, states=st)


@pytest.mark.parametrize(("size", "out", "band"), [(64, 16, 1), (64, 24, 3), (48, 48, 5)])
def test_base_at_a_size_from_texels_in_bands_is_the_whole_decode_resampled(
    monkeypatch, size, out, band
):
    """The base decoded and resampled band by band from its texels: the floats of the whole
    base decoded, then resampled (``asset_from_package``'s way), every bit."""
    rng = np.random.default_rng(size + out)
    texels = rng.integers(0, 256, (size, size, 3), dtype=np.uint8)
    texels[..., 2] |= 0x80  # z > 0 mostly; some texels at z = 0 (the horizon) as well
    texels[:2, :2, 2] = 127
    whole = pp._base_at(pp.decode_base(texels), (out, out), {})
    monkeypatch.setattr(pp, "band_rows", lambda w, b: band)
    monkeypatch.setattr(workset, "band_rows", lambda w, b: band)
    got = pp.decoded_base_at(texels, (out, out))
    assert got.dtype == np.float32 and got.shape == (out, out, 3)
    assert np.array_equal(got.view(U32), np.asarray(whole, np.float32).view(U32))


@pytest.mark.parametrize(("encoding", "states"), [("pd", 16), ("diff", 24), ("full", 48)])
def test_decode_errors_a_state_at_a_time_are_the_whole_packages(monkeypatch, encoding, states):
    """The report's decode errors: the numbers of the whole package decoded
    (``asset_from_package``) and each state compared, to the last bit."""
    asset = _asset(encoding, 48, states)
    pkg = pp.package_from_asset(asset)
    back = pp.asset_from_package(pkg)
    want = {
        name: {
            k: v
            for k, v in weighted_stats(angle_deg(asset.states[i], back.states[i])).to_json().items()
            if k.endswith("_deg")
        }
        for i, name in enumerate(asset.state_names)
    }
    assert any(v["max_deg"] > 0 for v in want.values())  # the 8-bit round trip is not exact
    monkeypatch.setattr(pp, "band_rows", lambda w, b: 2)
    monkeypatch.setattr(workset, "band_rows", lambda w, b: 2)
    got = decode_errors(asset, pkg)
    assert list(got) == list(want)
    for name in want:
        assert {k: np.float64(v).tobytes() for k, v in got[name].items()} == {
            k: np.float64(v).tobytes() for k, v in want[name].items()
        }
