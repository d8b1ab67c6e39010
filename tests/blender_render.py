"""Test harness, run by Blender 5's Python (``bpy``): render the exported node group's Normal
output.

    .venv-blender/bin/python tests/blender_render.py -- \
        OUT_DIR SIZE WEIGHTS.json [--color BASE.png] EXPORT/wrinkle_setup.json [...]

Builds the group with the export's own ``build_wrinkles.py`` (imported from the export folder),
puts it on a unit plane whose UVs are its x, y, seen by an orthographic camera that maps pixel
(row i, column j) to glTF uv ((j + 0.5) / SIZE, (i + 0.5) / SIZE) (Blender's v is 1 - glTF's v),
with the group's encoded normal as emission, and renders it with Cycles: one sample per pixel,
a 0.01-pixel box filter (the sample is at the pixel centre), no bounces, Standard view
transform: 32-bit float OpenEXR ``OUT_DIR/E_K.exr`` for export E and weight set K of
WEIGHTS.json (per export, a list of region-weight lists in the setup's region order). Cycles
evaluates the nodes on the CPU, without a GPU or a display. ``--color BASE.png``: render the
group's Color output instead (the colour states over the base colour BASE.png, an sRGB image
sampled at the same UVs, into BaseColor): linear light.
"""

from __future__ import annotations

import importlib.util
import json
import os
import sys

import bpy


def _load_builder(folder: str):
    """The export's own build_wrinkles.py as a module."""
    spec = importlib.util.spec_from_file_location(
        f"build_wrinkles_{abs(hash(folder))}", os.path.join(folder, "build_wrinkles.py")
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _scene(size: int) -> tuple:
    """Plane (UVs = x, y), orthographic camera, Cycles at one centred sample per pixel."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    mesh = bpy.data.meshes.new("plane")
    mesh.from_pydata([(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [], [(0, 1, 2, 3)])
    uv = mesh.uv_layers.new(name="UVMap")
    for loop in mesh.loops:
        uv.data[loop.index].uv = mesh.vertices[loop.vertex_index].co.xy
    obj = bpy.data.objects.new("plane", mesh)
    scene.collection.objects.link(obj)
    mat = bpy.data.materials.new("probe")  # Blender 5: a material always has its node tree
    nt = mat.node_tree
    nt.nodes.clear()
    uvn = nt.nodes.new("ShaderNodeUVMap")
    uvn.uv_map = "UVMap"
    gnode = nt.nodes.new("ShaderNodeGroup")
    emit = nt.nodes.new("ShaderNodeEmission")
    emit.inputs["Strength"].default_value = 1.0
    out = nt.nodes.new("ShaderNodeOutputMaterial")
    nt.links.new(emit.outputs["Emission"], out.inputs["Surface"])
    mesh.materials.append(mat)
    cam_data = bpy.data.cameras.new("cam")
    cam_data.type = "ORTHO"
    cam_data.ortho_scale = 1.0
    cam = bpy.data.objects.new("cam", cam_data)
    cam.location = (0.5, 0.5, 1.0)
    scene.collection.objects.link(cam)
    scene.camera = cam
    r = scene.render
    r.engine = "CYCLES"
    r.resolution_x = r.resolution_y = size
    r.resolution_percentage = 100
    r.image_settings.file_format = "OPEN_EXR"
    r.image_settings.color_depth = "32"
    r.image_settings.color_mode = "RGBA"
    c = scene.cycles
    c.device = "CPU"
    c.samples = 1
    c.use_adaptive_sampling = False
    c.use_denoising = False
    c.pixel_filter_type = "BOX"
    c.filter_width = 0.01
    c.max_bounces = 0
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    return scene, nt, uvn, gnode, emit


def main() -> None:
    args = sys.argv[sys.argv.index("--") + 1 :]
    out_dir, size, weights_path, setups = args[0], int(args[1]), args[2], args[3:]
    color_base = None
    if setups and setups[0] == "--color":
        color_base, setups = setups[1], setups[2:]
    with open(weights_path, encoding="utf-8") as f:
        weight_sets = json.load(f)
    scene, nt, uvn, gnode, emit = _scene(size)
    for e, setup_path in enumerate(setups):
        folder = os.path.dirname(os.path.abspath(setup_path))
        with open(setup_path, encoding="utf-8") as f:
            setup = json.load(f)
        setup["shader"].setdefault("baseLayout", "rgb")
        setup["shader"].setdefault("stateLayout", "rgb")
        gnode.node_tree = _load_builder(folder).build_group(setup, folder)
        nt.links.new(uvn.outputs["UV"], gnode.inputs["UV"])
        if color_base is None:
            nt.links.new(gnode.outputs["Normal"], emit.inputs["Color"])
        else:
            img = bpy.data.images.load(os.path.abspath(color_base), check_existing=True)
            img.colorspace_settings.name = "sRGB"
            tex = nt.nodes.new("ShaderNodeTexImage")
            tex.image, tex.interpolation, tex.extension = img, "Linear", "EXTEND"
            nt.links.new(uvn.outputs["UV"], tex.inputs["Vector"])
            nt.links.new(tex.outputs["Color"], gnode.inputs["BaseColor"])
            nt.links.new(gnode.outputs["Color"], emit.inputs["Color"])
        for k, weights in enumerate(weight_sets[e]):
            for reg, w in zip(setup["regions"], weights):
                gnode.inputs[reg["parameter"]].default_value = float(w)
            scene.render.filepath = os.path.join(os.path.abspath(out_dir), f"{e}_{k}.exr")
            bpy.ops.render.render(write_still=True)
    print(json.dumps({"wrinklepipe": "rendered", "exports": len(setups), "size": size}))


if __name__ == "__main__":
    main()
