"""A skinned glTF as the ``bones`` driver reads it: its skin and its joints over time.

The driver (:mod:`wrinklepipe.drivers.bones`) is given this through
:attr:`wrinklepipe.drivers.base.DriverContext.read_rig` rather than reading the file itself.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from wrinklepipe.gltf.meshes import gltf_animation_times, gltf_joint_world_matrices_at
from wrinklepipe.readers.meshes import load_mesh


class GltfRig:
    """The skin (joint names, per-vertex joints and weights) and first animation of a glTF/GLB."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self._mesh = load_mesh(self.path)
        self.joint_names: tuple[str, ...] = tuple(self._mesh.joint_names)
        self.joints = self._mesh.joints
        self.skin_weights = self._mesh.skin_weights

    def key_times(self) -> np.ndarray:
        """Sorted key times (seconds) of the first animation."""
        return gltf_animation_times(self.path)

    def joint_matrices(self, times: Sequence[float | None]) -> np.ndarray:
        """World matrices ``[len(times), J, 4, 4]`` of the joints (None: the rest pose)."""
        return gltf_joint_world_matrices_at(self.path, self._mesh, times)
