"""Test harness, run by Blender 5's Python (``bpy``): what Blender's glTF importer makes of a file.

    .venv-blender/bin/python tests/blender_import.py -- OUT.npz FILE.gltf

Imports FILE.gltf into an empty scene with the importer's defaults (as File > Import > glTF 2.0
does) and writes every custom vertex attribute (names starting with ``_``) of every imported
mesh to OUT.npz as ``MESH/ATTRIBUTE`` -> values ``[V, components]`` (float64), and
``OUT.npz.json``: per mesh, its vertex count and each attribute's Blender data type. An import
that raises exits 1 with Blender's traceback on stderr (the importer's own error).
"""

from __future__ import annotations

import json
import sys

import bpy
import numpy as np

#: Blender attribute data type -> (the foreach_get property, components).
_FIELDS = {
    "FLOAT": ("value", 1),
    "INT": ("value", 1),
    "INT8": ("value", 1),
    "BOOLEAN": ("value", 1),
    "FLOAT2": ("vector", 2),
    "INT32_2D": ("value", 2),
    "FLOAT_VECTOR": ("vector", 3),
    "FLOAT_COLOR": ("color", 4),
    "BYTE_COLOR": ("color", 4),
    "QUATERNION": ("value", 4),
}


def main() -> None:
    args = sys.argv[sys.argv.index("--") + 1 :]
    out, path = args[0], args[1]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=path)
    arrays, info = {}, {}
    for mesh in bpy.data.meshes:
        n = len(mesh.vertices)
        kinds = {}
        for attr in mesh.attributes:
            if not attr.name.startswith("_") or attr.domain != "POINT":
                continue
            prop, width = _FIELDS[attr.data_type]
            values = np.empty(n * width, np.float64)
            attr.data.foreach_get(prop, values)
            arrays[f"{mesh.name}/{attr.name}"] = values.reshape(n, width)
            kinds[attr.name] = attr.data_type
        info[mesh.name] = {"vertices": n, "attributes": kinds}
    np.savez(out, **arrays)
    with open(out + ".json", "w", encoding="utf-8") as f:
        json.dump(info, f)


if __name__ == "__main__":
    main()
