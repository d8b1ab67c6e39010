"""Test harness, run by Blender 5's Python (``bpy``): a Blender export played and baked by Cycles.

    .venv-blender/bin/python tests/blender_bake.py -- OUT_DIR SIZE EXPORT/wrinkle_setup.json F...

Runs the export's own ``build_wrinkles.py`` as a user does (it imports the export's glTF, builds
the WrinklePipe node group into the wrinkled material, one driver per region, and keys the
region properties from the export's curves), then for each frame F (a float: Blender frame, as
``build_wrinkles.py`` keys curve time t at ``1 + t * fps``) sets the scene there, so the keys
and drivers play the weights, reads the weights the group's inputs then hold, and has Cycles
(CPU) bake the wrinkled object's shading normal (the Principled BSDF's Normal, which the
script feeds from the group through a Normal Map node) in tangent space into a SIZE x SIZE
float image in the UV layout: one sample at each texel centre, no margin, alpha 0 where no
triangle covers the texel. Writes ``OUT_DIR/bake_K.exr`` (32-bit float, RGBA, the colour
``0.5 + 0.5 n``) and ``OUT_DIR/bake.json``: the frames, the region parameters, the weights at
each frame, the object and material, and the evaluated mesh's corners (``corners.npz``: vertex
index, UV, Blender's MikkTSpace tangent and sign per corner) so the test can compare Blender's
tangent frame with the TANGENT the glTF ships.
"""

from __future__ import annotations

import importlib.util
import json
import os
import sys

import bpy
import numpy as np


def _load_builder(folder: str):
    spec = importlib.util.spec_from_file_location(
        "build_wrinkles", os.path.join(folder, "build_wrinkles.py")
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _corners(obj) -> dict:
    mesh = obj.data
    uv_name = mesh.uv_layers.active.name
    mesh.calc_tangents(uvmap=uv_name)
    n = len(mesh.loops)
    vidx = np.empty(n, np.int32)
    mesh.loops.foreach_get("vertex_index", vidx)
    tangent = np.empty(n * 3, np.float32)
    mesh.loops.foreach_get("tangent", tangent)
    sign = np.empty(n, np.float32)
    mesh.loops.foreach_get("bitangent_sign", sign)
    uv = np.empty(n * 2, np.float32)
    mesh.uv_layers[uv_name].data.foreach_get("uv", uv)
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    return {
        "vertex": vidx,
        "tangent": tangent.reshape(-1, 3),
        "sign": sign,
        "uv": uv.reshape(-1, 2),
        "positions": co.reshape(-1, 3),
    }


def main() -> None:
    args = sys.argv[sys.argv.index("--") + 1 :]
    out_dir, size, setup_path = os.path.abspath(args[0]), int(args[1]), args[2]
    frames = [float(f) for f in args[3:]]
    folder = os.path.dirname(os.path.abspath(setup_path))
    with open(setup_path, encoding="utf-8") as f:
        setup = json.load(f)
    builder = _load_builder(folder)
    sys.argv = [os.path.join(folder, "build_wrinkles.py"), "--", setup_path]
    builder.main()  # imports the glTF, builds the group, drivers and keys; prints its summary
    obj, mat = builder.find_face(setup)
    group = mat.node_tree.nodes["wrinklepipe group"]
    params = [r["parameter"] for r in setup["regions"]]

    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device = "CPU"
    c.samples = 1
    c.use_adaptive_sampling = False
    c.use_denoising = False
    bake = scene.render.bake
    bake.margin = 0
    bake.normal_space = "TANGENT"
    bake.normal_r, bake.normal_g, bake.normal_b = "POS_X", "POS_Y", "POS_Z"
    bake.use_selected_to_active = False
    bake.target = "IMAGE_TEXTURES"
    img = bpy.data.images.new("wrinklepipe_bake", size, size, float_buffer=True, alpha=True)
    img.colorspace_settings.name = "Non-Color"
    node = mat.node_tree.nodes.new("ShaderNodeTexImage")
    node.image = img
    mat.node_tree.nodes.active = node  # the bake's target; connected to nothing
    for o in bpy.context.view_layer.objects:
        o.select_set(o == obj)
    bpy.context.view_layer.objects.active = obj

    weights = []
    for k, frame in enumerate(frames):
        scene.frame_set(int(frame), subframe=frame - int(frame))
        weights.append([float(group.inputs[p].default_value) for p in params])
        img.pixels.foreach_set(np.zeros(size * size * 4, np.float32))
        bpy.ops.object.bake(type="NORMAL")
        img.filepath_raw = os.path.join(out_dir, f"bake_{k}.exr")
        img.file_format = "OPEN_EXR"
        img.save()
    np.savez(os.path.join(out_dir, "corners.npz"), **_corners(obj))
    summary = {
        "frames": frames,
        "parameters": params,
        "weights": weights,
        "object": obj.name,
        "material": mat.name,
        "blender": bpy.app.version_string,
    }
    with open(os.path.join(out_dir, "bake.json"), "w", encoding="utf-8") as f:
        json.dump(summary, f)


if __name__ == "__main__":
    main()
