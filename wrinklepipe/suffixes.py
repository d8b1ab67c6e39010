"""The file suffixes of the mesh and scene formats wrinklepipe reads: the one list.

:mod:`wrinklepipe.readers.registry` keys its reader table
(:data:`~wrinklepipe.readers.registry.FORMATS`) by them; layers below it (a driver asking
whether a ``file`` is a glTF animation, the manifest's checks) ask here, so a format's
suffixes are written once.
"""

from __future__ import annotations

from pathlib import Path

GLTF_SUFFIXES = (".gltf", ".glb")
USD_SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")
OBJ_SUFFIXES = (".obj",)


def is_gltf(name: str | Path) -> bool:
    """Whether ``name`` (a path or a manifest string) names a .gltf/.glb file, in any case."""
    return Path(str(name)).suffix.lower() in GLTF_SUFFIXES


def is_usd(name: str | Path) -> bool:
    """Whether ``name`` names a USD file (.usd, .usda, .usdc, .usdz), in any case."""
    return Path(str(name)).suffix.lower() in USD_SUFFIXES
