"""The demo character prepared and packaged in memory: what the writers' tests and benches use."""

from __future__ import annotations

from dataclasses import replace

from wrinklepipe.demo import demo_asset
from wrinklepipe.package import WrinklePackage
from wrinklepipe.pipeline.drivers import expression_cycle
from wrinklepipe.pipeline.package import package_from_asset
from wrinklepipe.pipeline.prepare import prepare_mesh


def demo_package(size: int = 256, encoding: str = "pd") -> WrinklePackage:
    """The demo character, prepared and packaged (no files read): what the writers' tests use."""
    asset = demo_asset(size, encoding=encoding)
    asset = replace(asset, mesh=prepare_mesh(asset.mesh))
    return package_from_asset(asset, curves=[expression_cycle(asset)])
