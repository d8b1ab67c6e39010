"""The wrinkle description of a package, typed: what ``WRINKLEPIPE_wrinkle_maps`` says.

:class:`WrinkleMeta` is the format-neutral description a :class:`~wrinklepipe.package.
WrinklePackage` carries beside its mesh and stored textures (``pkg.meta``): the encoding, the
states, the region masks and their channel table, the regions, expressions, drivers, weights and
the block-compressed copies. Textures are named (a :class:`~wrinklepipe.package.
PackedTexture`'s ``name``), not indexed, so one description serves the glTF and the USD writer.

Two JSON forms, one shape:

- :meth:`WrinkleMeta.to_json` / :meth:`WrinkleMeta.from_json`: the description itself (textures
  by name, expressions as ``{expression: {region: weight}}``), for reports and round trips.
- :meth:`WrinkleMeta.to_extension` / :meth:`WrinkleMeta.from_extension`: the glTF material
  extension block (textures as ``textureInfo`` by index, expressions as per-region weight rows),
  validated by the shipped JSON Schema
  (``schemas/WRINKLEPIPE_wrinkle_maps/schema/material.WRINKLEPIPE_wrinkle_maps.schema.json``).
  The USD reader checks what it read against the same schema (:meth:`WrinkleMeta.check`).

Everything is frozen: a stage that changes the description makes a new one with
:func:`dataclasses.replace`. ``expressions`` and ``drivers`` hold plain JSON (dicts) that no one
mutates.
"""

from __future__ import annotations

import functools
import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import jsonschema

from wrinklepipe.paths import SCHEMAS_DIR

EXTENSION = "WRINKLEPIPE_wrinkle_maps"
SCHEMA_FILE = SCHEMAS_DIR / EXTENSION / "schema" / f"material.{EXTENSION}.schema.json"
#: The value-mapping version of an asset that records none (``mapping`` absent).
LEGACY_MAPPING = 1
#: The vertex attribute holding the spatial-hash vertex IDs, unless the extension names another.
VERTEX_ID_ATTRIBUTE = "_WRINKLE_VERTEX_ID"
#: The rest-pose wrinkle bias (``Mesh.colors``, RGBA): read as one VEC3/VEC4 attribute of this
#: name (what wrinklepipe wrote before 0.2), written as BIAS_CHANNEL_ATTRIBUTES.
BIAS_ATTRIBUTE = "_WRINKLE_BIAS"
#: The bias as one SCALAR FLOAT attribute per channel, so every custom attribute of a wrinkled
#: primitive has one shape (SCALAR, as ``_WRINKLE_VERTEX_ID``): Blender 5's glTF importer fails
#: on a primitive whose custom attributes mix shapes, for most PYTHONHASHSEED values.
BIAS_CHANNEL_ATTRIBUTES = tuple(f"{BIAS_ATTRIBUTE}_{c}" for c in "RGBA")
#: Longest schema message quoted in an error (a message quotes the offending value).
_MAX_MESSAGE = 240


@functools.cache
def extension_schema() -> dict[str, Any]:
    """The extension's JSON Schema (draft 2020-12), read once."""
    return json.loads(SCHEMA_FILE.read_text(encoding="utf-8"))


@functools.cache
def _validator() -> jsonschema.Draft202012Validator:
    return jsonschema.Draft202012Validator(extension_schema())


def schema_problems(ext: Any) -> list[tuple[str, str]]:
    """What the schema says is wrong with an extension block: ``(pointer, message)`` pairs,
    the pointer relative to the block (``/masks/table/2``), in document order."""
    errors = sorted(_validator().iter_errors(ext), key=lambda e: [str(p) for p in e.path])
    out = []
    for e in errors:
        pointer = "".join(f"/{p}" for p in e.path)
        message = e.message if len(e.message) <= _MAX_MESSAGE else e.message[:_MAX_MESSAGE] + "..."
        out.append((pointer, message))
    return out


@dataclass(frozen=True)
class StateMeta:
    """A wrinkle state: its name, the stored texture holding its normal map, and its colour
    map's (``color``; None: the state does not change the colour). ``normal`` False: a
    colour-only state, whose stored normal map is the base's (it adds no relief; every
    consumer reads it as any other state)."""

    name: str
    texture: str
    color: str | None = None
    normal: bool = True

    def to_json(self) -> dict[str, Any]:
        d: dict[str, Any] = {"name": self.name, "texture": self.texture}
        if self.color is not None:
            d["color"] = self.color
        if not self.normal:
            d["normal"] = False
        return d

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> StateMeta:
        color = d.get("color")
        return cls(
            str(d["name"]),
            str(d.get("texture", "")),
            None if color is None else str(color),
            bool(d.get("normal", True)),
        )


@dataclass(frozen=True)
class RegionMeta:
    """A region: its name, side and the states it drives (empty: all states)."""

    name: str
    side: str = "center"
    states: tuple[str, ...] = ()

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "side": self.side, "states": list(self.states)}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> RegionMeta:
        return cls(str(d["name"]), str(d.get("side", "center")), tuple(d.get("states", ())))


@dataclass(frozen=True)
class SplitRef:
    """The texture channel that splits an lr-split slot into its left and right member."""

    texture: int
    channel: str


@dataclass(frozen=True)
class MaskChannel:
    """One channel-table entry (docs/regions.md): a region's mask is ``channel`` of mask texture
    ``texture``, or (``array`` layout) the single channel of texture ``layer``; lr-split entries
    record their ``side`` and, off the centre, the ``split`` channel."""

    region: str
    texture: int | None = None
    channel: str | None = None
    layer: int | None = None
    side: str | None = None
    split: SplitRef | None = None

    @property
    def index(self) -> int:
        """The mask texture this entry reads (``layer`` or ``texture``)."""
        return int(self.layer if self.layer is not None else self.texture)  # type: ignore[arg-type]

    def to_json(self) -> dict[str, Any]:
        d: dict[str, Any] = {"region": self.region}
        for key in ("texture", "channel", "layer", "side"):
            if getattr(self, key) is not None:
                d[key] = getattr(self, key)
        if self.split is not None:
            d["split"] = {"texture": self.split.texture, "channel": self.split.channel}
        return d

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> MaskChannel:
        def opt_int(key: str) -> int | None:
            return None if d.get(key) is None else int(d[key])

        split = d.get("split")
        return cls(
            region=str(d["region"]),
            texture=opt_int("texture"),
            channel=None if d.get("channel") is None else str(d["channel"]),
            layer=opt_int("layer"),
            side=None if d.get("side") is None else str(d["side"]),
            split=None if not split else SplitRef(int(split["texture"]), str(split["channel"])),
        )


@dataclass(frozen=True)
class MaskMeta:
    """The region masks: the packing ``layout``, the mask textures (by name) and the table."""

    layout: str
    textures: tuple[str, ...]
    table: tuple[MaskChannel, ...]

    def table_json(self) -> list[dict[str, Any]]:
        """The channel table as JSON (what :func:`wrinklepipe.masks.unpack` reads)."""
        return [e.to_json() for e in self.table]

    def to_json(self) -> dict[str, Any]:
        return {"layout": self.layout, "textures": list(self.textures), "table": self.table_json()}

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> MaskMeta:
        return cls(
            str(d["layout"]),
            tuple(str(n) for n in d["textures"]),
            tuple(MaskChannel.from_json(e) for e in d["table"]),
        )


@dataclass(frozen=True)
class CompressedCopy:
    """A block-compressed copy of a base or state texture shipped beside its PNG: the KTX2 and
    DDS files (relative to the asset; ``dds`` empty for a KTX2-only format such as UASTC)."""

    texture: str
    format: str
    layout: str
    mapping: int
    levels: int
    ktx2: str
    dds: str
    #: "srgb": a colour map's copy in an sRGB block format (mips made in linear light)
    color_space: str = "linear"

    def to_json(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "texture": self.texture,
            "format": self.format,
            "layout": self.layout,
            "mapping": self.mapping,
            "levels": self.levels,
            "ktx2": self.ktx2,
            "dds": self.dds,
        }
        if self.color_space != "linear":
            d["color_space"] = self.color_space
        return d

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> CompressedCopy:
        return cls(
            str(d["texture"]),
            str(d["format"]),
            str(d["layout"]),
            int(d["mapping"]),
            int(d["levels"]),
            str(d["ktx2"]),
            str(d["dds"]),
            str(d.get("color_space", "linear")),
        )


#: ``texture(info, pointer, role)`` -> the name of the stored texture a ``textureInfo`` shows;
#: role is ``"state"``, ``"mask"`` or ``"copy"`` (a compressed copy's: a texture already named).
TextureName = Callable[[Any, str, str], str]
#: ``err(message, pointer)`` -> the error to raise.
ErrorFactory = Callable[[str, str], Exception]


@dataclass(frozen=True)
class WrinkleMeta:
    """The wrinkle description of a package (the extension's content, textures by name)."""

    encoding: str
    policy: str
    states: tuple[StateMeta, ...]
    masks: MaskMeta
    regions: tuple[RegionMeta, ...]
    scale: float = 1.0
    mapping: int = LEGACY_MAPPING
    #: ``{expression: {region: weight}}``, sorted by expression and region
    expressions: dict[str, dict[str, float]] = field(default_factory=dict)
    #: the driver tables, as in the source manifest
    drivers: tuple[dict[str, Any], ...] = ()
    #: one static weight per region
    weights: tuple[float, ...] = ()
    compressed: tuple[CompressedCopy, ...] = ()
    #: the base colour's stored texture when states carry colour (glTF: the wrinkled
    #: material's baseColorTexture), and the linear factor it is multiplied by
    base_color: str | None = None
    color_factor: tuple[float, float, float] = (1.0, 1.0, 1.0)

    # -- views --------------------------------------------------------------------------------
    @property
    def state_names(self) -> list[str]:
        return [s.name for s in self.states]

    @property
    def state_textures(self) -> list[str]:
        return [s.texture for s in self.states]

    @property
    def region_names(self) -> list[str]:
        return [r.name for r in self.regions]

    @property
    def color_states(self) -> list[int]:
        """Indices of the states that carry a colour map."""
        return [k for k, s in enumerate(self.states) if s.color is not None]

    @property
    def color_textures(self) -> list[str]:
        """The colour maps' stored textures, in state order."""
        return [s.color for s in self.states if s.color is not None]

    @property
    def texture_copies(self) -> list[str]:
        """The textures with a block-compressed copy."""
        return [c.texture for c in self.compressed]

    @property
    def versioned(self) -> bool:
        """Whether the state textures use a value mapping (pd, diff) rather than n = 2 v - 1."""
        return self.encoding in ("pd", "diff")

    # -- the description's own JSON -------------------------------------------------------------
    def to_json(self) -> dict[str, Any]:
        """The description as JSON (textures by name; ``compressed`` only when there are any)."""
        d: dict[str, Any] = {
            "encoding": self.encoding,
            "scale": self.scale,
            "mapping": self.mapping,
            "policy": self.policy,
            "states": [s.to_json() for s in self.states],
            "masks": self.masks.to_json(),
            "regions": [r.to_json() for r in self.regions],
            "expressions": {e: dict(row) for e, row in self.expressions.items()},
            "drivers": [dict(x) for x in self.drivers],
            "weights": list(self.weights),
        }
        if self.compressed:
            d["compressed"] = [c.to_json() for c in self.compressed]
        if self.base_color is not None:
            d["base_color"] = self.base_color
            d["color_factor"] = list(self.color_factor)
        return d

    @classmethod
    def from_json(cls, d: Mapping[str, Any]) -> WrinkleMeta:
        """Inverse of :meth:`to_json` (the schema's defaults for what is absent)."""
        regions = tuple(RegionMeta.from_json(r) for r in d["regions"])
        return cls(
            encoding=str(d["encoding"]),
            policy=str(d["policy"]),
            states=tuple(StateMeta.from_json(s) for s in d["states"]),
            masks=MaskMeta.from_json(d["masks"]),
            regions=regions,
            scale=float(d.get("scale", 1.0)),
            mapping=int(d.get("mapping", LEGACY_MAPPING)),
            expressions=sorted_expressions(d.get("expressions", {})),
            drivers=tuple(dict(x) for x in d.get("drivers", ())),
            weights=tuple(float(w) for w in d.get("weights", [0.0] * len(regions))),
            compressed=tuple(CompressedCopy.from_json(c) for c in d.get("compressed", ())),
            base_color=None if d.get("base_color") is None else str(d["base_color"]),
            color_factor=_factor(d.get("color_factor")),
        )

    # -- the glTF extension block ---------------------------------------------------------------
    def to_extension(
        self, tex_index: Mapping[str, int], vertex_id_attribute: str = VERTEX_ID_ATTRIBUTE
    ) -> dict[str, Any]:
        """The ``WRINKLEPIPE_wrinkle_maps`` JSON: textures by glTF texture index."""
        names = self.region_names
        ext: dict[str, Any] = {
            "encoding": self.encoding,
            "scale": float(self.scale),
            "mapping": int(self.mapping),
            "policy": self.policy,
            "states": [_state_entry(s, tex_index) for s in self.states],
            "masks": {
                "layout": self.masks.layout,
                "textures": [{"index": tex_index[n]} for n in self.masks.textures],
                "table": self.masks.table_json(),
            },
            "regions": [r.to_json() for r in self.regions],
            "expressions": [
                {"name": e, "weights": [float(row.get(n, 0.0)) for n in names]}
                for e, row in self.expressions.items()
            ],
            "drivers": [dict(x) for x in self.drivers],
            "weights": [float(w) for w in self.weights],
            "vertexIdAttribute": vertex_id_attribute,
        }
        if self.compressed:
            ext["compressed"] = [_copy_entry(c, tex_index) for c in self.compressed]
        return ext

    @classmethod
    def from_extension(
        cls, ext: Any, texture: TextureName, err: ErrorFactory, pointer: str = ""
    ) -> WrinkleMeta:
        """The description an extension block holds, checked against the schema first.

        ``texture(info, pointer, role)`` names the stored texture of each ``textureInfo`` (the
        reader loads it); ``err(message, pointer)`` makes the error raised for the first
        problem (pointers are ``pointer`` + the place in the block)."""
        problems = schema_problems(ext)
        if problems:
            where, message = problems[0]
            raise err(f"extension block does not match its schema: {message}", pointer + where)
        states = tuple(
            StateMeta(
                s["name"],
                texture(s["texture"], f"{pointer}/states/{i}", "state"),
                None
                if "colorTexture" not in s
                else texture(s["colorTexture"], f"{pointer}/states/{i}/colorTexture", "color"),
                bool(s.get("normal", True)),
            )
            for i, s in enumerate(ext["states"])
        )
        masks = ext["masks"]
        mask_names = tuple(
            texture(t, f"{pointer}/masks/textures/{i}", "mask")
            for i, t in enumerate(masks["textures"])
        )
        regions = tuple(RegionMeta.from_json(g) for g in ext["regions"])
        names = [g.name for g in regions]
        expressions = {}
        for e in ext.get("expressions", []):
            if len(e["weights"]) != len(names):
                raise err(
                    f"expression {e['name']!r} has {len(e['weights'])} weights for "
                    f"{len(names)} regions",
                    f"{pointer}/expressions",
                )
            expressions[e["name"]] = dict(zip(names, e["weights"]))
        table = tuple(MaskChannel.from_json(e) for e in masks["table"])
        for i, e in enumerate(table):
            if not 0 <= e.index < len(mask_names):
                raise err(
                    f"channel table entry {i} points at mask texture {e.index}, which does "
                    "not exist",
                    f"{pointer}/masks/table/{i}",
                )
        copies = []
        for i, c in enumerate(ext.get("compressed", [])):
            ktx2, dds = (list(c["uris"]) + ["", ""])[:2]
            copies.append(
                CompressedCopy(
                    texture(c["texture"], f"{pointer}/compressed/{i}", "copy"),
                    c["format"],
                    c["layout"],
                    int(c.get("mapping", LEGACY_MAPPING)),
                    int(c["levels"]),
                    ktx2,
                    dds,
                    str(c.get("colorSpace", "linear")),
                )
            )
        return cls(
            encoding=ext["encoding"],
            policy=ext["policy"],
            states=states,
            masks=MaskMeta(masks["layout"], mask_names, table),
            regions=regions,
            scale=float(ext.get("scale", 1.0)),
            mapping=int(ext.get("mapping", LEGACY_MAPPING)),  # assets before v2 record none
            expressions=sorted_expressions(expressions),
            drivers=tuple(dict(d) for d in ext.get("drivers", [])),
            weights=tuple(float(w) for w in ext["weights"]),
            compressed=tuple(copies),
        )

    def check(self, err: ErrorFactory, pointer: str = "") -> WrinkleMeta:
        """This description, if its extension form passes the schema (what a USD reader
        calls on what it read); else the first problem through ``err``."""
        names = sorted(
            {
                *self.state_textures,
                *self.color_textures,
                *self.masks.textures,
                *self.texture_copies,
                *([self.base_color] if self.base_color is not None else []),
            }
        )
        problems = schema_problems(self.to_extension({n: i for i, n in enumerate(names)}))
        if problems:
            where, message = problems[0]
            raise err(f"wrinkle description does not match the schema: {message}", pointer)
        return self


def _state_entry(s: StateMeta, tex_index: Mapping[str, int]) -> dict[str, Any]:
    """A state's extension entry: its normal map's textureInfo, its colour map's (sRGB) and,
    for a colour-only state, ``normal: false``."""
    d: dict[str, Any] = {"name": s.name, "texture": {"index": tex_index[s.texture]}}
    if s.color is not None:
        d["colorTexture"] = {"index": tex_index[s.color]}
    if not s.normal:
        d["normal"] = False
    return d


def _copy_entry(c: CompressedCopy, tex_index: Mapping[str, int]) -> dict[str, Any]:
    d: dict[str, Any] = {
        "texture": {"index": tex_index[c.texture]},
        "format": c.format,
        "layout": c.layout,
        "mapping": int(c.mapping),
        "levels": int(c.levels),
        "uris": [u for u in (c.ktx2, c.dds) if u],  # uastc: a KTX2 only
    }
    if c.color_space != "linear":
        d["colorSpace"] = c.color_space
    return d


def _factor(value: Any) -> tuple[float, float, float]:
    if value is None:
        return (1.0, 1.0, 1.0)
    r, g, b = (float(x) for x in list(value)[:3])
    return (r, g, b)


def sorted_expressions(rows: Mapping[str, Mapping[str, Any]]) -> dict[str, dict[str, float]]:
    """``{expression: {region: weight}}`` as floats, sorted by expression and by region."""
    return {e: {r: float(w) for r, w in sorted(row.items())} for e, row in sorted(rows.items())}


def table_from_json(table: Sequence[Mapping[str, Any]]) -> tuple[MaskChannel, ...]:
    """A channel table (JSON, as :func:`wrinklepipe.masks.pack` returns it) as entries."""
    return tuple(MaskChannel.from_json(e) for e in table)
