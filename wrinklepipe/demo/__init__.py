"""The built-in demo character: generated, cached, and written out as artist source files."""

from __future__ import annotations

import numpy as np

from wrinklepipe.asset import Mesh, Region, WrinkleAsset
from wrinklepipe.demo.character import DemoCharacter, generate
from wrinklepipe.demo.colors import demo_colors
from wrinklepipe.options import BudgetOptions

__all__ = ["DemoCharacter", "generate", "demo_asset", "demo_mesh"]


def demo_mesh(character: DemoCharacter) -> Mesh:
    """The demo head as an :class:`wrinklepipe.asset.Mesh`."""
    m = character.mesh
    return Mesh(
        positions=m.positions,
        indices=m.indices,
        uvs=m.uvs,
        normals=m.normals,
        morph_names=m.morph_names,
        morph_deltas=m.morph_deltas,
        name="demo_head",
    )


def demo_asset(
    size: int = 1024,
    encoding: str = "pd",
    policy: str = "clamp01",
    mesh_resolution: tuple[int, int] = (96, 64),
    color: bool = False,
) -> WrinkleAsset:
    """The demo as an in-memory asset at full resolution (maps and masks ``size`` x ``size``).

    ``states`` hold the wrinkled face (base + wrinkle height) at full activation, so every encoding
    can be derived from them; the paper's reduced sizes are in ``resolution``. ``color``: with
    colour states (:func:`wrinklepipe.demo.colors.demo_colors`: pale where the skin stretches,
    flushed where it compresses).
    """

    c = generate(size, mesh_resolution=mesh_resolution)

    states = np.stack([c.wrinkled_normal(k) for k in range(len(c.state_names))])
    return WrinkleAsset(
        name="demo",
        base=c.base_normal,
        states=states,
        state_names=c.state_names,
        masks=c.masks,
        regions=tuple(Region(n, s) for n, s in zip(c.region_names, c.region_sides)),
        expressions=c.expressions,
        encoding=encoding,
        policy=policy,
        pd_scale=1.0,
        mesh=demo_mesh(c),
        budget=BudgetOptions(max_mean_deg=0.5, max_p99_deg=2.0),
        resolution={"base": size, "wrinkle": max(size // 4, 4), "mask": max(size // 16, 4)},
        provenance={"generator": "wrinklepipe.demo", "seed": c.seed, "size": size},
        color=demo_colors(c.base_height, c.state_names) if color else None,
    )
