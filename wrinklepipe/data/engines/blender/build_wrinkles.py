"""wrinklepipe: build the wrinkle node group and its drivers in Blender from wrinkle_setup.json.

    blender -b --python-exit-code 1 --python build_wrinkles.py -- [SETUP.json] [--save OUT.blend]

or run it from Blender's text editor (it reads the wrinkle_setup.json next to it). It imports the
export's glTF when the scene has no mesh, builds the node group ``WrinklePipe`` (the wrinkle
model of wrinklepipe.model in shader nodes: masks through the channel table, region weights,
the asset's policy and encoding), inserts it into the wrinkled material (the glTF material named
in the setup's ``materials``, else the one sampling the base normal map: UV Map -> WrinklePipe
-> Normal Map -> the BSDF's Normal), gives the mesh object one custom property per region
(``wp_<region>``) with a driver into the material, and keys those properties from the export's
weight curves. With colour states (the setup's ``colors``) the group also blends their colour
maps (sRGB images) over the material's base colour with the same activations, in linear
light: whatever fed the BSDF's Base Color now feeds the group's BaseColor, and its Color the
BSDF. Prints a JSON summary on its last line.
"""

from __future__ import annotations

import json
import os
import sys
from typing import Any

import bpy
from bpy_extras import anim_utils

Val = Any  # a node socket or a constant
CH = "rgba"


def _args() -> tuple[str, str | None]:
    argv = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else []
    here = os.path.dirname(os.path.abspath(__file__))
    setup = os.path.join(here, "wrinkle_setup.json")
    save = None
    rest = list(argv)
    while rest:
        a = rest.pop(0)
        if a == "--save":
            save = rest.pop(0)
        else:
            setup = a
    return os.path.abspath(setup), save


# ------------------------------------------------------------------------------------------------
# small node helpers (Blender 3.x, 4.x and 5.x; tested with Blender 5.0)


class Graph:
    def __init__(self, tree: Any) -> None:
        self.tree = tree
        self.nodes = tree.nodes
        self.links = tree.links
        self.x = 0

    def node(self, kind: str, **props: Any) -> Any:
        n = self.nodes.new(kind)
        for k, v in props.items():
            setattr(n, k, v)
        n.location = (self.x, -len(self.nodes) * 12)
        return n

    def link(self, a: Any, b: Any) -> None:
        self.links.new(a, b)

    def math(self, op: str, a: Val, b: Val = None, c: Val = None, clamp: bool = False) -> Any:
        n = self.node("ShaderNodeMath", operation=op, use_clamp=clamp)
        for i, v in enumerate((a, b, c)):
            if v is not None:
                self._in(n.inputs[i], v)
        return n.outputs[0]

    def vmath(self, op: str, a: Val, b: Val = None, scale: Val = None) -> Any:
        n = self.node("ShaderNodeVectorMath", operation=op)
        self._in(n.inputs[0], a)
        if b is not None:
            self._in(n.inputs[1], b)
        if scale is not None:
            self._in(n.inputs["Scale"], scale)
        return n.outputs["Vector"] if op not in ("DOT_PRODUCT", "LENGTH") else n.outputs["Value"]

    def _in(self, socket: Any, value: Val) -> None:
        if isinstance(value, bpy.types.NodeSocket):
            self.link(value, socket)
        else:
            socket.default_value = value

    def combine(self, x: Val, y: Val, z: Val) -> Any:
        n = self.node("ShaderNodeCombineXYZ")
        for i, v in enumerate((x, y, z)):
            self._in(n.inputs[i], v)
        return n.outputs[0]

    def separate(self, vec: Val) -> Any:
        n = self.node("ShaderNodeSeparateXYZ")
        self._in(n.inputs[0], vec)
        return n.outputs

    def image(self, path: str, uv: Any, colorspace: str = "Non-Color") -> Any:
        img = bpy.data.images.load(path, check_existing=True)
        img.colorspace_settings.name = colorspace
        img.alpha_mode = "CHANNEL_PACKED"
        n = self.node("ShaderNodeTexImage", image=img, interpolation="Linear", extension="EXTEND")
        self.link(uv, n.inputs["Vector"])
        return n

    def channels(self, tex: Any) -> tuple[Any, Any, Any, Any]:
        """(r, g, b, a) sockets of an image node."""
        sep = self.separate(tex.outputs["Color"])
        return (sep[0], sep[1], sep[2], tex.outputs["Alpha"])

    def add_all(self, terms: list[Any]) -> Val:
        terms = [t for t in terms if t is not None]
        if not terms:
            return 0.0
        acc = terms[0]
        for t in terms[1:]:
            acc = self.math("ADD", acc, t)
        return acc


def _socket(tree: Any, name: str, in_out: str, kind: str) -> Any:
    if hasattr(tree, "interface"):  # Blender 4.x
        return tree.interface.new_socket(name=name, in_out=in_out, socket_type=kind)
    coll = tree.inputs if in_out == "INPUT" else tree.outputs
    return coll.new(kind, name)


# ------------------------------------------------------------------------------------------------
# the model in nodes


def build_group(setup: dict[str, Any], folder: str) -> Any:
    name = "WrinklePipe"
    old = bpy.data.node_groups.get(name)
    if old is not None:
        bpy.data.node_groups.remove(old)
    tree = bpy.data.node_groups.new(name, "ShaderNodeTree")
    g = Graph(tree)
    _socket(tree, "UV", "INPUT", "NodeSocketVector")
    regions = setup["regions"]
    for r in regions:
        _socket(tree, r["parameter"], "INPUT", "NodeSocketFloat")
    colors = setup.get("colors")
    if colors:
        _socket(tree, "BaseColor", "INPUT", "NodeSocketColor")
    _socket(tree, "Normal", "OUTPUT", "NodeSocketColor")
    _socket(tree, "Activity", "OUTPUT", "NodeSocketFloat")
    if colors:
        _socket(tree, "Color", "OUTPUT", "NodeSocketColor")
    gin = g.node("NodeGroupInput")
    gout = g.node("NodeGroupOutput")
    uv = gin.outputs["UV"]
    weight = {r["name"]: gin.outputs[r["parameter"]] for r in regions}

    # masks: one image per mask texture, the channel table (lr-split: c * s, c * (1 - s))
    masks = setup["masks"]
    mask_ch = [g.channels(g.image(os.path.join(folder, f), uv)) for f in masks["files"]]
    table = {e["region"]: e for e in masks["table"]}
    m = {}
    for r in regions:
        e = table[r["name"]]
        if "layer" in e:
            v = mask_ch[int(e["layer"])][0]
        else:
            v = mask_ch[int(e["texture"])][CH.index(e["channel"])]
            if e.get("split") and e.get("side") in ("left", "right"):
                s = mask_ch[int(e["split"]["texture"])][CH.index(e["split"]["channel"])]
                if e["side"] == "right":
                    s = g.math("SUBTRACT", 1.0, s)
                v = g.math("MULTIPLY", v, s)
        m[r["name"]] = v

    states = [s["name"] for s in setup["states"]]
    policy = setup["policy"]
    if policy == "renormalize":
        total = g.add_all(list(m.values()))
        div = g.math("MAXIMUM", total, 1.0)
        m = {k: g.math("DIVIDE", v, div) for k, v in m.items()}

    def drives(r: dict[str, Any], s: str) -> bool:
        return not r.get("states") or s in r["states"]

    if policy == "signed":
        sig = g.add_all([g.math("MULTIPLY", m[r["name"]], weight[r["name"]]) for r in regions])
        sig = g.math("MINIMUM", g.math("MAXIMUM", sig, -1.0), 1.0)
        act = [g.math("MAXIMUM", g.math("MULTIPLY", sig, -1.0), 0.0), g.math("MAXIMUM", sig, 0.0)]
    else:
        act = []
        for s in states:
            terms = [
                g.math("MULTIPLY", m[r["name"]], weight[r["name"]]) for r in regions if drives(r, s)
            ]
            a = g.add_all(terms)
            act.append(a if policy == "additive" else g.math("ADD", a, 0.0, clamp=True))
        if policy == "lerp":
            div = g.math("MAXIMUM", g.add_all(act), 1.0)
            act = [g.math("DIVIDE", a, div) for a in act]
    activity = g.add_all([g.math("ABSOLUTE", a) for a in act])

    # decode: normal maps n = 2 v - 1 (z rebuilt for two-channel maps); pd / diff through the
    # value mapping of wrinkle_setup.json (t = v mul + add, clamped at -1 under v2)
    def normal(color: Any, layout: str) -> Any:
        n = g.vmath("SUBTRACT", g.vmath("MULTIPLY", color, (2.0, 2.0, 2.0)), (1.0, 1.0, 1.0))
        if layout == "rg":
            x, y, _ = g.separate(n)
            xx_yy = g.math("ADD", g.math("MULTIPLY", x, x), g.math("MULTIPLY", y, y))
            z = g.math("SQRT", g.math("MAXIMUM", g.math("SUBTRACT", 1.0, xx_yy), 0.0))
            n = g.combine(x, y, z)
        return g.vmath("NORMALIZE", n)

    mp = setup["stateMapping"]

    def signed(color: Any) -> Any:
        t = g.vmath("ADD", g.vmath("MULTIPLY", color, (mp["mul"],) * 3), (mp["add"],) * 3)
        if mp.get("clampMin") is not None:
            t = g.vmath("MAXIMUM", t, (mp["clampMin"],) * 3)
        return t

    shader = setup["shader"]
    base_img = g.image(os.path.join(folder, setup["base"]["file"]), uv)
    b = normal(base_img.outputs["Color"], "rgb" if shader["baseLayout"] == "rgb" else "rg")
    bx, by, bz = g.separate(b)
    enc = setup["encoding"]
    scale = float(setup["scale"])
    if enc == "pd":
        inv = g.math("DIVIDE", 1.0, g.math("MAXIMUM", bz, 1e-12))
        ax, ay, az = g.math("MULTIPLY", bx, inv), g.math("MULTIPLY", by, inv), 1.0
    else:
        ax, ay, az = bx, by, bz
    for k, s in enumerate(setup["states"]):
        tex = g.image(os.path.join(folder, s["file"]), uv)
        a = act[k]
        if enc == "pd":
            wx, wy, _ = g.separate(g.vmath("SCALE", signed(tex.outputs["Color"]), scale=scale))
            ax = g.math("MULTIPLY_ADD", a, wx, ax)
            ay = g.math("MULTIPLY_ADD", a, wy, ay)
        elif enc == "diff":
            dx, dy, dz = g.separate(
                g.vmath("SCALE", signed(tex.outputs["Color"]), scale=1.0 / scale)
            )
            ax, ay, az = (
                g.math("MULTIPLY_ADD", a, d, acc) for d, acc in ((dx, ax), (dy, ay), (dz, az))
            )
        else:
            wn = normal(tex.outputs["Color"], "rgb" if shader["stateLayout"] == "rgb" else "rg")
            wx, wy, wz = g.separate(wn)
            if enc == "full":
                ax = g.math("MULTIPLY_ADD", a, g.math("SUBTRACT", wx, bx), ax)
                ay = g.math("MULTIPLY_ADD", a, g.math("SUBTRACT", wy, by), ay)
                az = g.math("MULTIPLY_ADD", a, g.math("SUBTRACT", wz, bz), az)
            else:  # composite: x, y add, z multiplies
                ax = g.math("MULTIPLY_ADD", a, wx, ax)
                ay = g.math("MULTIPLY_ADD", a, wy, ay)
                az = g.math(
                    "MULTIPLY", az, g.math("MULTIPLY_ADD", a, g.math("SUBTRACT", wz, 1.0), 1.0)
                )
    n = g.vmath("NORMALIZE", g.combine(ax, ay, az))
    col = g.vmath("ADD", g.vmath("MULTIPLY", n, (0.5, 0.5, 0.5)), (0.5, 0.5, 0.5))
    g.link(col, gout.inputs["Normal"])
    if colors:
        # colour: C = clamp(C_B + sum_k a_k (C_k - C_B), 0, 1), linear (sRGB images decode)
        base_color = gin.outputs["BaseColor"]
        acc = base_color
        index = {s: k for k, s in enumerate(states)}
        for c in colors["states"]:
            ck = g.image(os.path.join(folder, c["file"]), uv, "sRGB").outputs["Color"]
            delta = g.vmath("SUBTRACT", ck, base_color)
            acc = g.vmath("ADD", acc, g.vmath("SCALE", delta, scale=act[index[c["name"]]]))
        acc = g.vmath("MINIMUM", g.vmath("MAXIMUM", acc, (0.0, 0.0, 0.0)), (1.0, 1.0, 1.0))
        g.link(acc, gout.inputs["Color"])
    g.link(
        activity if isinstance(activity, bpy.types.NodeSocket) else g.math("ADD", 0.0, 0.0),
        gout.inputs["Activity"],
    )
    return tree


# ------------------------------------------------------------------------------------------------
# material, drivers, curves


def _uses_image(mat: Any, base_name: str) -> bool:
    if mat is None or mat.node_tree is None:
        return False
    return any(
        n.type == "TEX_IMAGE" and n.image and os.path.basename(n.image.filepath) == base_name
        for n in mat.node_tree.nodes
    )


def _named(mat: Any, names: list[str]) -> bool:
    """``mat`` is one of the glTF materials ``names`` (Blender suffixes clashes: ``.001``)."""
    return mat is not None and any(mat.name == n or mat.name.startswith(n + ".") for n in names)


def find_face(setup: dict[str, Any]) -> tuple[Any, Any] | None:
    """(object, material) of the mesh with the wrinkled material (by the glTF material's name
    in ``setup["materials"]``, else the material that samples the base normal map), or None."""
    names = setup.get("materials") or []
    base_name = os.path.basename(setup["base"]["file"])
    for test in (lambda m: _named(m, names), lambda m: _uses_image(m, base_name)):
        for obj in bpy.context.scene.objects:
            if obj.type != "MESH":
                continue
            for slot in obj.material_slots:
                if test(slot.material):
                    return obj, slot.material
    return None


def install(obj: Any, mat: Any, group: Any, setup: dict[str, Any]) -> int:
    nt = mat.node_tree
    for n in [n for n in nt.nodes if n.name.startswith("wrinklepipe")]:
        nt.nodes.remove(n)
    bsdf = next((n for n in nt.nodes if n.type == "BSDF_PRINCIPLED"), None)
    if bsdf is None:
        bsdf = nt.nodes.new("ShaderNodeBsdfPrincipled")
    gnode = nt.nodes.new("ShaderNodeGroup")
    gnode.node_tree = group
    gnode.name = "wrinklepipe group"
    uvn = nt.nodes.new("ShaderNodeUVMap")
    uvn.name = "wrinklepipe uv"
    nmap = nt.nodes.new("ShaderNodeNormalMap")
    nmap.name = "wrinklepipe normal map"
    nmap.space = "TANGENT"
    nt.links.new(uvn.outputs["UV"], gnode.inputs["UV"])
    nt.links.new(gnode.outputs["Normal"], nmap.inputs["Color"])
    nt.links.new(nmap.outputs["Normal"], bsdf.inputs["Normal"])
    if setup.get("colors"):  # the base colour through the group: the colour states over it
        socket = bsdf.inputs["Base Color"]
        if socket.is_linked:
            link = socket.links[0]
            nt.links.new(link.from_socket, gnode.inputs["BaseColor"])
            nt.links.remove(link)
        else:
            gnode.inputs["BaseColor"].default_value = socket.default_value
        nt.links.new(gnode.outputs["Color"], socket)
    drivers = 0
    for r in setup["regions"]:
        prop = r["parameter"]
        if prop not in obj:
            obj[prop] = 0.0
        sock = gnode.inputs[prop]
        fc = sock.driver_add("default_value")
        var = fc.driver.variables.new()
        var.name = "w"
        var.type = "SINGLE_PROP"
        var.targets[0].id_type = "OBJECT"
        var.targets[0].id = obj
        var.targets[0].data_path = f'["{prop}"]'
        fc.driver.expression = "w"
        drivers += 1
    return drivers


def key_curves(obj: Any, setup: dict[str, Any], folder: str) -> int:
    fps = bpy.context.scene.render.fps / bpy.context.scene.render.fps_base
    keys = 0
    for rel in setup.get("curves", []):
        if not rel.endswith(".json"):
            continue
        with open(os.path.join(folder, rel), encoding="utf-8") as f:
            c = json.load(f)
        n = c["regionCount"]
        for i, t in enumerate(c["times"]):
            for r, prop in enumerate(c["regions"]):
                obj[prop] = c["values"][i * n + r]
                obj.keyframe_insert(data_path=f'["{prop}"]', frame=1 + t * fps, group="wrinklepipe")
                keys += 1
        break  # the first curve; others are in the JSON for your own actions
    for fc in _fcurves(obj):
        if fc.group is not None and fc.group.name == "wrinklepipe":
            for kp in fc.keyframe_points:
                kp.interpolation = "LINEAR"
    return keys


def _fcurves(obj: Any) -> list[Any]:
    """The F-curves of ``obj``'s action: its slot's channelbag (Blender 4.4+ slotted actions;
    Blender 5 has no ``Action.fcurves``), else the action's own list (Blender 3.x, 4.0-4.3)."""
    ad = obj.animation_data
    action = ad.action if ad is not None else None
    if action is None:
        return []
    if hasattr(action, "layers"):
        bag = anim_utils.action_get_channelbag_for_slot(action, ad.action_slot)
        return list(bag.fcurves) if bag is not None else []
    return list(action.fcurves)


def _numpy_bool_shim() -> None:
    """Blender 3.4's glTF importer uses ``np.bool``, which numpy 1.24 removed (Debian bookworm
    ships that pair); give it the builtin it meant."""
    try:
        import numpy as np
    except ImportError:
        return
    if "bool" not in np.__dict__:
        np.bool = bool


def main() -> None:
    path, save = _args()
    folder = os.path.dirname(path)
    with open(path, encoding="utf-8") as f:
        setup = json.load(f)
    setup["shader"].setdefault("baseLayout", "rgb")
    setup["shader"].setdefault("stateLayout", "rgb")
    found = find_face(setup)
    if found is None:  # not in the scene yet: import the export's glTF
        _numpy_bool_shim()
        bpy.ops.import_scene.gltf(filepath=os.path.join(folder, setup["mesh"]))
        found = find_face(setup)
    if found is None:
        raise RuntimeError(
            f"no mesh with the material {setup.get('materials')} or one that uses "
            f"{setup['base']['file']} (import {setup['mesh']} first)"
        )
    obj, mat = found
    group = build_group(setup, folder)
    drivers = install(obj, mat, group, setup)
    keys = key_curves(obj, setup, folder)
    if save:
        bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(save))
    print(
        json.dumps(
            {
                "wrinklepipe": "ok",
                "group": group.name,
                "nodes": len(group.nodes),
                "object": obj.name,
                "material": mat.name,
                "drivers": drivers,
                "keys": keys,
            }
        )
    )


if __name__ == "__main__":
    main()
