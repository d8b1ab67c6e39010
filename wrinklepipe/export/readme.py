"""The README of an engine export: what is in the folder and how to import it."""

from __future__ import annotations

from typing import Any

from wrinklepipe.names import plural


def _files(files: list[str]) -> str:
    return "\n".join(f"- `{f}`" for f in files if f != "README.md")


def _common(doc: dict[str, Any]) -> str:
    notes = "\n".join(f"- {n}" for n in doc["notes"]) or "- none"
    states = ", ".join(s["name"] for s in doc["states"])
    materials = " / ".join(f"`{m}`" for m in doc.get("materials", [])) or "the face's"
    return (
        f"The wrinkled material: {materials} in `{doc['mesh']}` (apply the wrinkle shader to the "
        "surfaces using it; every other part and material is as in the source).\n\n"
        f"Encoding `{doc['encoding']}` (scale {doc['scale']}, value mapping v{doc['mapping']}), "
        f"policy `{doc['policy']}`, {plural(len(doc['states']), 'state')} ({states}), "
        f"{plural(len(doc['regions']), 'region')}, normal maps in the {doc['convention']} "
        "convention "
        f"({'+Y' if doc['convention'] == 'opengl' else '-Y'}).\n\n"
        "The shader is wrinklepipe's one template (the numpy model `wrinklepipe.model`, "
        "rendered equal to it in wrinklepipe's tests); `wrinkle_setup.json` describes everything "
        "(files, the channel table, the slot table that places each region weight in the "
        "shader's weight array). Region weights are one number per region, in "
        "`wrinkle_setup.json`'s region order; `parameter` is each region's name in this "
        "engine. Curves: `curves/NAME.json` (times, then the weights of every region per key).\n\n"
        f"Notes:\n{notes}\n"
    )


def _unreal(doc: dict[str, Any]) -> str:
    n_masks = len(doc["masks"]["files"])
    return f"""\
## Import into Unreal Engine 5

1. Import `{doc["mesh"]}` (Interchange glTF importer: skeletal mesh with its morph targets and
   animations; the wrinkled material comes without its base normal map, which is in
   `textures/`, and the wrinkle material below replaces it; other materials keep their textures).
2. Import the textures in `textures/`. For `base_normal` and the `wrinkle_*` maps set
   Compression Settings **Normalmap (BC5)** for `.dds` files (they are BC5 with full mip chains;
   set Mip Gen Settings **LeaveExistingMips**), sRGB **off**, and do **not** flip the green
   channel: they are already DirectX (-Y). `.png` maps: sRGB off, Compression **Masks (no sRGB)**
   or VectorDisplacementmap. The {n_masks} mask textures: sRGB off, Compression **Masks**.
3. Make a Material Function (or edit the face material) with the two **Custom** nodes: open
   `{doc["unreal"]["clipboard"]}` in a text editor, copy all of it and paste it into the
   material graph (Ctrl+V). That makes both nodes with their code, output type and named input
   pins, unconnected. (The text follows the format of Unreal 5's material-editor copies; it was
   not pasted into Unreal where wrinklepipe is tested. If your editor refuses it, make the
   nodes by hand as below.)
   - `WP_Decode`: Output Type Float 1, no inputs, Code = the contents of `WP_Decode.hlsl`.
   - `WP_Wrinkle`: Output Type Float 3, Code = the contents of `WP_Wrinkle.hlsl`, inputs in
     this order (names exactly as listed in `wrinkle_setup.json` `unreal.nodes[1].inputs`):
     `UV` (TexCoord 0), `Base`, `State0`..., `Mask0`... (Texture Object nodes holding the
     textures of `wrinkle_setup.json` in order), one scalar per region (a Scalar Parameter named
     like the input), and `Decode` (the WP_Decode node's output).
   Connect the inputs as listed and `WP_Wrinkle` to the material's **Normal** (tangent space).
   With many textures set the Texture Objects' Sampler Source to Shared: Wrap.
4. Drive the region scalar parameters: import `curves/NAME.csv` as a **CurveTable** (one row per
   region, named like the parameters) and set the parameters from it in the Animation Blueprint
   or a Sequencer track, or add Material curves of the same names to the morph animation.
"""


def _unity(doc: dict[str, Any]) -> str:
    base = doc["base"]["file"]
    n_states, n_masks = doc["statesArray"]["layers"], doc["masks"]["layers"]
    return f"""\
## Import into Unity (URP/HDRP Shader Graph)

1. Copy the whole folder into `Assets/` (with the `.meta` files: they hold the texture import
   settings, so the textures import right without a click):
   - the base normal map `{base}`:
     Texture Type **Normal map** (Unity stores it in its own normal-map encoding; the wrinkle
     shader reads it as `UnpackNormal` does), Generate Mip Maps on.
   - `textures/wrinkle_states.png` / `textures/wrinkle_masks.png`: Texture Shape **2D Array**,
     Columns 1, Rows {n_states} / {n_masks}; Texture Type Default, sRGB **off**, Alpha Source From
     Input (mask data, not transparency).
   - All three: mip maps with the Box filter, Filter Mode Trilinear, Wrap Mode Clamp, Compression
     **None** (the texels wrinklepipe's tests render). To save memory choose Normal or High
     Quality compression instead; the error is then that of Unity's encoder (not measured here).
   The GUIDs in the `.meta` files come from the asset's name and the file's path: exporting the
   asset again and copying the folder over keeps every material's texture references.
2. Import `{doc["mesh"]}` with glTFast or UnityGLTF (mesh, blend shapes, animation clip).
3. In the face's Shader Graph add a **Custom Function** node: Type File, Source
   `WrinkleMaps.hlsl`, Name `WrinkleNormal`, Precision Float; inputs UV (Vector 2), BaseMap
   (Texture 2D), States (Texture 2D Array), Masks (Texture 2D Array), Sampler (Sampler State);
   outputs NormalTS (Vector 3), Activity (Float). Connect NormalTS to the Fragment **Normal
   (Tangent Space)** block (the graph's Fragment Normal Space: Tangent).
4. Add `WrinkleWeights.cs` to the face: Setup = `wrinkle_setup.json`, Curve = a
   `curves/NAME.json`, Target = the face's Renderer; set Sync to its Animator to play the
   wrinkles in step with the blend-shape clip, or write `Weights[r]` from your own code.
"""


def _godot(doc: dict[str, Any]) -> str:
    base = doc["base"]["file"]
    n_states, n_masks = doc["statesArray"]["layers"], doc["masks"]["layers"]
    return f"""\
## Import into Godot 4

1. Copy the folder into the project with the `.import` files (they hold the import settings:
   Godot imports the textures with them, no re-import by hand):
   - the base normal map `{base}`:
     Texture2D, Normal Map **Enable**, Lossless, mipmaps generated, no Y flip (the map is
     already +Y), 3D detection off (it stays lossless).
   - `textures/wrinkle_states.png` / `textures/wrinkle_masks.png`: **Texture2DArray**, Slices
     Horizontal 1 / Vertical {n_states} / {n_masks}, Lossless, mipmaps generated.
   Each `.import` has a fixed `uid` (from the asset's name and the file's path): exporting the
   asset again and copying the folder over keeps every reference to the textures. Godot adds
   the imported paths on the first import. VRAM Compressed saves memory at the cost of Godot's
   encoder's error (not measured here).
2. Let Godot import `{doc["mesh"]}` (mesh, blend shapes and animations in an AnimationPlayer).
3. Give the face surface a **ShaderMaterial** with `wrinkle.gdshader`; set `wp_base` to the base
   normal map, `wp_states` / `wp_masks` to the two arrays and `wp_albedo` to the colour map.
4. Add a Node with `wrinkle_weights.gd`: mesh = the face, setup_path = `wrinkle_setup.json`,
   curve_path = a `curves/NAME.json`, animation_player = the imported AnimationPlayer (so the
   wrinkles follow the blend-shape animation), or set `weights[r]` from your own code.
   `wp_show_regions` on the material shows where wrinkles are active.
"""


def _blender(doc: dict[str, Any]) -> str:
    return f"""\
## Import into Blender

Run the script (it imports `{doc["mesh"]}` when the scene has no mesh yet, builds the
`WrinklePipe` node group from `wrinkle_setup.json`, puts it between the face material's UVs and
its Normal Map node, adds one custom property per region on the object with a driver into the
group, and keys those properties from `curves/*.json`):

```sh
blender -b --python-exit-code 1 --python build_wrinkles.py -- wrinkle_setup.json --save face.blend
```

or from Blender's Scripting workspace: open `build_wrinkles.py` and Run Script (it looks for
`wrinkle_setup.json` next to itself). The region weights are the object's custom properties
`wp_<region>`; the node group's inputs are the same weights, so any rig can drive them.
"""


#: How each export is proven where wrinklepipe is tested. Of the four targets only Blender
#: installs from a package registry (PyPI ``bpy``); Unreal, Unity and Godot 4 do not, so their
#: shader code is compiled and rendered outside the engine instead.
_TESTED = {
    "unreal": (
        "Unreal Engine does not run where wrinklepipe is tested (no package registry has it). "
        "What is tested: `WP_Wrinkle.hlsl`, compiled by glslang (HLSL -> SPIR-V) and "
        "spirv-cross (-> GLSL) and rendered with OpenGL on the exported BC5 texels, equals "
        "wrinklepipe's numpy model (green negated) within 0.5 degrees mean and 2 p99; the DDS "
        "files are read back by an independent BC5 decoder; the clipboard text is parsed. "
        "Nothing here was opened in Unreal."
    ),
    "unity": (
        "Unity does not run where wrinklepipe is tested (no package registry has it). What is "
        "tested: `WrinkleMaps.hlsl`, compiled by glslang (HLSL -> SPIR-V) and spirv-cross "
        "(-> GLSL) and rendered with OpenGL on the exported strips, equals wrinklepipe's numpy "
        "model within 0.5 degrees mean and 2 p99; the `.meta` files are parsed as YAML. "
        "`WrinkleWeights.cs` and the import were not run in Unity."
    ),
    "godot": (
        "Godot 4 does not run where wrinklepipe is tested (no package registry has it). What is "
        "tested: the core of `wrinkle.gdshader`, as GLSL, rendered with OpenGL on the exported "
        "strips, equals wrinklepipe's numpy model within 0.5 degrees mean and 2 p99; the "
        "`.import` files are parsed. `wrinkle_weights.gd` and the import were not run in Godot."
    ),
    "blender": (
        "Tested with Blender 5.0 (PyPI `bpy` 5.x) in wrinklepipe's default test run: this "
        "script, run as above, imports the glTF (custom attributes kept), builds the node "
        "group, drivers and keys; at curve keys the group's inputs equal the curves, and Cycles' "
        "bake of the shaded normal equals wrinklepipe's numpy model within 1 degree mean and 3 "
        "p99. The script keeps working with Blender 3.x and 4.x (not tested)."
    ),
}


def readme(doc: dict[str, Any], files: list[str]) -> str:
    """README.md for an export described by ``doc`` (``wrinkle_setup.json``)."""
    steps = {"unreal": _unreal, "unity": _unity, "godot": _godot, "blender": _blender}[
        doc["engine"]
    ]
    return (
        f"# {doc['mesh'].rsplit('.', 1)[0]} for {doc['title']}\n\n"
        "Written by `wrinklepipe export`.\n\n"
        + _common(doc)
        + "\n"
        + steps(doc)
        + "\n## How this export is tested\n\n"
        + _TESTED[doc["engine"]]
        + "\n\n## Files\n\n"
        + _files(files + ["README.md"])
        + "\n"
    )
