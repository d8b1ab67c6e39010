"""The poses the validator judges: those the asset's drivers produce.

:func:`render_poses` is what the render pass draws (:func:`wrinklepipe.drivers.poses.driver_poses`
on the input's curves: neutral, the expression table when an expressions driver or none plays
it, each other curve's per-region peak frames); :func:`fidelity_poses` the same poses without
neutral (nothing is active there), as the fidelity measure takes them.
"""

from __future__ import annotations

import numpy as np

from wrinklepipe import fidelity as fd
from wrinklepipe.drivers.poses import DriverPose, driver_poses
from wrinklepipe.package import WeightCurves
from wrinklepipe.validate.inputs import ValidationInput


def render_poses(inp: ValidationInput) -> list[DriverPose]:
    """The poses the render pass draws (:func:`wrinklepipe.drivers.poses.driver_poses` on the
    input's curves; curves known only by their values are keyed by frame index)."""
    curves = list(inp.curves)
    if not curves:
        curves = [
            WeightCurves(name, np.arange(len(v), dtype=np.float32), np.asarray(v, np.float32))
            for name, v in sorted(inp.weight_curves.items())
        ]
    return driver_poses(inp.asset, curves)


def fidelity_poses(inp: ValidationInput) -> list[fd.Pose]:
    """The render pass's poses but neutral, as :class:`wrinklepipe.fidelity.Pose`."""
    return [fd.Pose(p.name, p.weights) for p in render_poses(inp) if p.name != "neutral"]
