"""Weight drivers: where the region weights come from (see docs/regions.md).

Every driver returns linear weights ``[frames, regions, states]`` in a :class:`DriverResult`;
:func:`evaluate` runs one by kind. Kinds: ``curves``, ``expressions``, ``blendshapes``, ``bones``,
``dynamic`` (the last plugs in :mod:`wrinklepipe.geometry.dynamic`).
"""

from __future__ import annotations

from wrinklepipe.drivers import blendshapes, bones, curves, dynamic, expressions
from wrinklepipe.drivers.base import (
    DEFAULT_FPS,
    DRIVERS,
    DriverContext,
    DriverResult,
    evaluate,
    frame_times,
    policy_weights,
    register,
)

KINDS: tuple[str, ...] = ("curves", "expressions", "blendshapes", "bones", "dynamic")

__all__ = [
    "DEFAULT_FPS",
    "DRIVERS",
    "KINDS",
    "DriverContext",
    "DriverResult",
    "blendshapes",
    "bones",
    "curves",
    "dynamic",
    "evaluate",
    "expressions",
    "frame_times",
    "policy_weights",
    "register",
]
