"""The wrinkle material as a MaterialX 1.39 document, in standard-library nodes only.

For hosts that render MaterialX (Houdini/Karma, Omniverse, Maya/LookdevX, usdview/Storm, through
USD's UsdMtlx or natively). The USD writer puts the document beside the layer and references
it from the wrinkle material (:mod:`wrinklepipe.usd.package_write`); UsdPreviewSurface stays the
fallback for hosts without MaterialX.

The document holds one nodegraph, ``NG_wrinkle``, with the whole model of
:mod:`wrinklepipe.model` as nodes (``image``, ``extract``, ``multiply``, ``add``,
``subtract``, ``divide``, ``max``, ``min``, ``clamp``, ``sqrt``, ``dotproduct``,
``normalize``, ``combine3``), a ``normalmap`` node and a ``standard_surface``:

- one float interface input per region, ``w_<region>`` (the region's weight; a USD layer
  animates them), and one filename interface input per map (``base``, ``state_<k>``,
  ``mask_<l>``, paths relative to the document);
- the masks through the channel table (``lr-split``: ``c * s``, ``c * (1 - s)``), the sums
  ``s_k = sum_r M_r w_rk`` and the asset's policy (``clamp01``, ``signed``, ``additive``,
  ``renormalize``, ``lerp``) as nodes;
- each texel decoded by the codec's value mapping (``t = v mul + add``, clamped at -1 under
  mapping v2) and combined by the asset's encoding (``pd``, ``diff``, ``full``,
  ``composite``), then normalised: output ``normal_ts`` is the unit tangent-space normal
  (+Y), ``normal`` the ``normalmap`` of it (world space), which feeds
  ``SR_wrinkle.normal``; ``activity`` is ``sum_k |a_k|``.

With colour states (``setup.has_color``) the graph also reads the base colour (``base_color``)
and each colour map (``color_<c>``) as ``srgb_texture`` images, blends them with the same
activations in linear light (``C = clamp(C_B + sum_k a_k (C_k - C_B), 0, 1)``, the base times
the colour factor) and outputs ``color``, which feeds ``SR_wrinkle.base_color``. MaterialX
converts an image's colour space after it samples it: a host that filters such an image in its
encoded values (rather than decoding each texel first, as a GPU's sRGB sampler does) differs
slightly between texels.

Normal maps and masks are read linear (no colour space), with linear filtering and clamped
addressing.
MaterialX's texture coordinates are USD's ``st``: ``(u, 1 - v)`` of glTF's ``uv``, the very
same texels.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache

import MaterialX as mx

from wrinklepipe import codec
from wrinklepipe.shading.setup import ShaderSetup

NODEGRAPH = "NG_wrinkle"
SHADER = "SR_wrinkle"
MATERIAL = "M_wrinkle"
#: Where UsdMtlx puts the material when a USD layer references the document.
USD_MATERIAL_PATH = f"/MaterialX/Materials/{MATERIAL}"
#: The base colour and roughness of the surface (the UsdPreviewSurface fallback's).
BASE_COLOR = (0.8, 0.62, 0.52)
ROUGHNESS = 0.55


@dataclass(frozen=True)
class MapFiles:
    """The maps' file names as the document references them (relative to the document):
    ``base``, one per state (the setup's state order), one per mask texture (layer order)."""

    base: str
    states: tuple[str, ...]
    masks: tuple[str, ...]
    #: with colour states: the base colour and the colour maps (the setup's colour order)
    base_color: str = ""
    colors: tuple[str, ...] = ()
    color_factor: tuple[float, float, float] = (1.0, 1.0, 1.0)


def ident(name: str) -> str:
    """A MaterialX (and USD) identifier for ``name``."""
    out = re.sub(r"[^A-Za-z0-9_]", "_", name) or "x"
    return out if not out[0].isdigit() else "_" + out


def weight_input(region: str) -> str:
    """The nodegraph input that holds ``region``'s weight."""
    return "w_" + ident(region)


#: The library files holding the definitions of every node the document uses.
DEFINITION_FILES = (
    "libraries/stdlib/stdlib_defs.mtlx",
    "libraries/pbrlib/pbrlib_defs.mtlx",
    "libraries/bxdf/standard_surface.mtlx",
)


@cache
def definitions() -> mx.Document:
    """The standard node definitions the document uses (loaded once; ~20 ms, a fifth of the
    whole library): enough to name each node's definition."""
    lib = mx.createDocument()
    for rel in DEFINITION_FILES:
        mx.readFromXmlFile(lib, rel, mx.getDefaultDataSearchPath())
    return lib


@cache
def library() -> mx.Document:
    """MaterialX's standard data libraries, implementations included (loaded once)."""
    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
    return lib


class _IntValue(int):
    """An integer input value (``extract``'s index)."""


class _Graph:
    """Typed node helpers on one nodegraph: values are nodes (with their type) or constants."""

    def __init__(self, graph: mx.NodeGraph) -> None:
        self.g = graph
        self.n = 0

    def node(self, category: str, out_type: str, name: str = "", **inputs: object) -> mx.Node:
        self.n += 1
        node = self.g.addNode(category, name or f"n{self.n}_{category}", out_type)
        for key, value in inputs.items():
            self.set(node, key.rstrip("_"), value)
        return node

    @staticmethod
    def type_of(value: object) -> str:
        if isinstance(value, mx.Node):
            return value.getType()
        if isinstance(value, mx.Input):
            return value.getType()
        if isinstance(value, float | int):
            return "float"
        return {2: "vector2", 3: "vector3", 4: "vector4"}[len(value)]  # type: ignore[arg-type]

    def set(self, node: mx.Node, key: str, value: object) -> None:
        if isinstance(value, _IntValue):
            node.addInput(key, "integer").setValue(int(value))
            return
        kind = self.type_of(value)
        inp = node.addInput(key, kind)
        if isinstance(value, mx.Node):
            inp.setConnectedNode(value)
        elif isinstance(value, mx.Input):  # an interface input of the graph
            inp.setInterfaceName(value.getName())
        elif kind == "float":
            inp.setValue(float(value))  # type: ignore[arg-type]
        else:
            inp.setValueString(", ".join(repr(float(v)) for v in value))  # type: ignore[union-attr]
            inp.setType(kind)

    def op(self, category: str, a: object, b: object) -> mx.Node:
        """A two-input math node (``in1``, ``in2``); the output has ``a``'s type (a vector op
        with a float ``b`` is MaterialX's ``FA`` form)."""
        kind = self.type_of(a)
        if kind == "float" and self.type_of(b) != "float":
            a, b, kind = b, a, self.type_of(b)  # only for commutative ops (add, multiply)
            assert category in ("add", "multiply"), category
        return self.node(category, kind, in1=a, in2=b)

    def mul(self, a: object, b: object) -> mx.Node:
        return self.op("multiply", a, b)

    def add(self, a: object, b: object) -> mx.Node:
        return self.op("add", a, b)

    def sub(self, a: object, b: object) -> mx.Node:
        return self.op("subtract", a, b)

    def div(self, a: object, b: object) -> mx.Node:
        return self.op("divide", a, b)

    def max(self, a: object, b: object) -> mx.Node:
        return self.op("max", a, b)

    def min(self, a: object, b: object) -> mx.Node:
        return self.op("min", a, b)

    def clamp(self, a: object, low: float, high: float) -> mx.Node:
        return self.node("clamp", self.type_of(a), in_=a, low=low, high=high)

    def extract(self, v: mx.Node, index: int) -> mx.Node:
        return self.node("extract", "float", in_=v, index=_IntValue(index))

    def combine3(self, x: object, y: object, z: object) -> mx.Node:
        return self.node("combine3", "vector3", in1=x, in2=y, in3=z)

    def total(self, terms: Sequence[object]) -> object:
        acc: object = 0.0
        for i, t in enumerate(terms):
            acc = t if i == 0 else self.add(acc, t)
        return acc


def _image(g: _Graph, key: str, file: str, kind: str, colorspace: str = "") -> mx.Node:
    """An ``image`` node reading ``file`` through the graph's filename input ``key``: linear
    filtering, clamped addressing; ``colorspace``: the file's (``srgb_texture`` for colour
    maps), converted to the document's linear working space."""
    inp = g.g.addInput(key, "filename")
    inp.setValueString(file)
    if colorspace:
        inp.setColorSpace(colorspace)
    node = g.node("image", kind, name=f"img_{key}")
    file_input = node.addInput("file", "filename")
    file_input.setInterfaceName(key)
    if colorspace:  # where colour management reads it
        file_input.setColorSpace(colorspace)
    for k, v in (("filtertype", "linear"), ("uaddressmode", "clamp"), ("vaddressmode", "clamp")):
        node.addInput(k, "string").setValueString(v)
    return node


def _masks(g: _Graph, setup: ShaderSetup, files: MapFiles) -> list[mx.Node]:
    """``M_r`` per region through the channel table (lr-split: ``c * s``, ``c * (1 - s)``)."""
    kinds = {1: "float", 2: "vector2", 3: "vector3", 4: "vector4"}
    images = [
        _image(g, f"mask_{i}", f, kinds[c])
        for i, (f, c) in enumerate(zip(files.masks, setup.layer_channels, strict=True))
    ]

    def channel(layer: int, ch: int) -> mx.Node:
        node = images[layer]
        return node if node.getType() == "float" else g.extract(node, ch)

    split = channel(*setup.split) if setup.split is not None else None
    one_minus_split = g.sub(1.0, split) if split is not None else None
    m = []
    for e in setup.entries:
        c = channel(e.layer, e.channel)
        if e.part == 1:
            c = g.mul(c, split)
        elif e.part == 2:
            c = g.mul(c, one_minus_split)
        m.append(c)
    return m


def _activations(
    g: _Graph, setup: ShaderSetup, m: list[mx.Node], w_in: list[mx.Input]
) -> list[object]:
    """``a_k = policy(s_k)``, ``s_k = sum_r M_r w_rk`` (``signed``: one signed sum)."""
    policy = setup.policy
    mw = [g.mul(m[r], w_in[r]) for r in range(setup.n_regions)]
    if policy == "signed":
        sig = g.clamp(g.total(mw), -1.0, 1.0)
        return [g.max(g.mul(sig, -1.0), 0.0), g.max(sig, 0.0)]
    sums = [
        g.total([mw[r] for r in range(setup.n_regions) if setup.region_states[r][k]])
        for k in range(setup.n_states)
    ]
    if policy == "additive":
        return sums
    if policy == "renormalize":
        div = g.max(g.total(m), 1.0)
        sums = [g.div(s, div) for s in sums]
    act: list[object] = [g.clamp(s, 0.0, 1.0) for s in sums]
    if policy == "lerp":
        div = g.max(g.total(act), 1.0)
        act = [g.div(a, div) for a in act]
    return act


def _unit_normal(g: _Graph, texel: mx.Node, layout: str) -> mx.Node:
    """A normal-map texel decoded: ``normalize(2 v - 1)`` (``rg``: z rebuilt)."""
    v = g.sub(g.mul(texel, 2.0), 1.0)
    if layout == "rg":
        x, y = g.extract(v, 0), g.extract(v, 1)
        xx_yy = g.add(g.mul(x, x), g.mul(y, y))
        v = g.combine3(x, y, g.node("sqrt", "float", in_=g.max(g.sub(1.0, xx_yy), 0.0)))
    return g.node("normalize", "vector3", in_=v)


def _combined(g: _Graph, setup: ShaderSetup, files: MapFiles, act: list[object]) -> mx.Node:
    """``normalize(combine(B, {W_k, a_k}, encoding))``: the texels decoded by the codec's value
    mapping (``t = v mul + add``, clamped at -1 under v2), combined as wrinklepipe.model does."""
    mul, add = codec.encoding(setup.encoding).mapping(setup.mapping).affine(setup.state_bits)
    clamp_low = setup.mapping >= 2 and setup.state_bits > 0

    def signed(texel: mx.Node) -> mx.Node:
        t = g.add(g.mul(texel, float(mul)), float(add))
        return g.max(t, -1.0) if clamp_low else t

    b = _unit_normal(g, _image(g, "base", files.base, "vector3"), setup.base_layout)
    bx, by, bz = (g.extract(b, i) for i in range(3))
    enc, scale = setup.encoding, float(setup.scale)
    if enc == "pd":
        inv = g.div(1.0, g.max(bz, 1e-12))
        ax, ay, az = g.mul(bx, inv), g.mul(by, inv), 1.0
    else:
        ax, ay, az = bx, by, bz
    for k, file in enumerate(files.states):
        a = act[k]
        texel = _image(g, f"state_{k}", file, "vector3")
        if enc == "pd":
            d = g.mul(signed(texel), scale)
            ax = g.add(ax, g.mul(g.extract(d, 0), a))
            ay = g.add(ay, g.mul(g.extract(d, 1), a))
        elif enc == "diff":
            d = g.div(signed(texel), scale)
            ax, ay, az = (
                g.add(acc, g.mul(g.extract(d, i), a)) for i, acc in enumerate((ax, ay, az))
            )
        else:
            wn = _unit_normal(g, texel, setup.state_layout)
            wx, wy, wz = (g.extract(wn, i) for i in range(3))
            if enc == "full":
                ax = g.add(ax, g.mul(g.sub(wx, bx), a))
                ay = g.add(ay, g.mul(g.sub(wy, by), a))
                az = g.add(az, g.mul(g.sub(wz, bz), a))
            else:  # composite: x, y add, z multiplies
                ax = g.add(ax, g.mul(wx, a))
                ay = g.add(ay, g.mul(wy, a))
                az = g.mul(az, g.add(g.mul(g.sub(wz, 1.0), a), 1.0))
    return g.node("normalize", "vector3", name="wrinkled", in_=g.combine3(ax, ay, az))


def _color(g: _Graph, setup: ShaderSetup, files: MapFiles, act: list[object]) -> mx.Node:
    """The colour model: ``clamp(C_B + sum_k a_k (C_k - C_B), 0, 1)`` in linear light."""
    if not files.base_color or len(files.colors) != len(setup.color_states):
        raise ValueError("MaterialX output: colour states need the base colour and their maps")
    base = _image(g, "base_color", files.base_color, "color3", "srgb_texture")
    if tuple(files.color_factor) != (1.0, 1.0, 1.0):
        factor = g.node("constant", "color3", name="color_factor")
        factor.addInput("value", "color3").setValueString(
            ", ".join(repr(float(x)) for x in files.color_factor)
        )
        base = g.mul(base, factor)
    acc: object = base
    for c, k in enumerate(setup.color_states):
        ck = _image(g, f"color_{c}", files.colors[c], "color3", "srgb_texture")
        acc = g.add(acc, g.mul(g.sub(ck, base), act[k]))
    return g.node("clamp", "color3", name="wrinkled_color", in_=acc, low=0.0, high=1.0)


def wrinkle_document(
    setup: ShaderSetup, files: MapFiles, weights: Sequence[float] | None = None
) -> mx.Document:
    """The wrinkle material of ``setup`` as a MaterialX document (see the module docstring);
    ``weights``: the regions' default weights (0 when None). Raises ``ValueError`` for what
    the document does not express: a map layout other than ``rgb`` / ``rg``."""
    setup.check()
    for which, layout in (("base", setup.base_layout), ("state", setup.state_layout)):
        if layout not in ("rgb", "rg"):
            raise ValueError(f"MaterialX output reads {which} maps as rgb or rg, not {layout}")
    doc = mx.createDocument()
    graph = doc.addNodeGraph(NODEGRAPH)
    graph.setDocString("wrinklepipe: the wrinkle model (wrinklepipe.model) in MaterialX nodes")
    g = _Graph(graph)
    w = list(weights) if weights is not None else [0.0] * setup.n_regions
    w_in = []
    for r, name in enumerate(setup.region_names):
        inp = graph.addInput(weight_input(name), "float")
        inp.setValue(float(w[r]))
        w_in.append(inp)
    act = _activations(g, setup, _masks(g, setup, files), w_in)
    absval = [g.node("absval", "float", in_=a) if isinstance(a, mx.Node) else a for a in act]
    activity = g.total(absval)
    n = _combined(g, setup, files, act)
    nmap = g.node("normalmap", "vector3", name="normalmap", in_=g.add(g.mul(n, 0.5), 0.5))
    nmap.setNodeDefString("ND_normalmap_float")
    for name, node in (("normal_ts", n), ("normal", nmap)):
        graph.addOutput(name, "vector3").setConnectedNode(node)
    out = graph.addOutput("activity", "float")
    if not isinstance(activity, mx.Node):
        activity = g.node("constant", "float", value=float(activity))  # type: ignore[arg-type]
    out.setConnectedNode(activity)
    if setup.has_color:
        graph.addOutput("color", "color3").setConnectedNode(_color(g, setup, files, act))

    surface = doc.addNode("standard_surface", SHADER, "surfaceshader")
    if setup.has_color:
        base_color = surface.addInput("base_color", "color3")
        base_color.setNodeGraphString(NODEGRAPH)
        base_color.setOutputString("color")
    else:
        surface.addInput("base_color", "color3").setValueString(", ".join(map(str, BASE_COLOR)))
    surface.addInput("specular_roughness", "float").setValue(ROUGHNESS)
    normal = surface.addInput("normal", "vector3")
    normal.setNodeGraphString(NODEGRAPH)
    normal.setOutputString("normal")
    doc.addMaterialNode(MATERIAL, surface)
    return doc


def validate(doc: mx.Document) -> str:
    """MaterialX's own validation of ``doc`` against the standard libraries: "" when valid,
    else its message."""
    checked = mx.createDocument()
    checked.copyContentFrom(doc)
    checked.importLibrary(library())
    ok, message = checked.validate()
    return "" if ok else message


def to_xml(doc: mx.Document) -> bytes:
    """The document as MaterialX XML (the libraries it uses are referenced, not copied)."""
    return mx.writeToXmlString(doc).encode("utf-8")
