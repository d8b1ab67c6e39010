"""The package's layers and which may import which: the one table the docs and the tests share.

Each layer may import itself and the layers listed before it, never a later one; a module
belongs to the layer of the longest prefix below that names it. ``tests/test_architecture.py``
parses every module's imports (module level and deferred alike) and checks them against this
table, and that the module graph has no circle; ``docs/architecture.md`` shows the table,
generated from it (``python -m wrinklepipe.layers``; a test keeps the page current).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Layer:
    """One layer: a name, what lives there, and the module prefixes it holds."""

    name: str
    holds: str
    prefixes: tuple[str, ...]


LAYERS: tuple[Layer, ...] = (
    Layer(
        "core",
        "the wrinkle model, codec and measure (numpy only), plain data types, errors, staged "
        "writes, terminal output, presets",
        (
            "wrinklepipe",
            "wrinklepipe.paths",
            "wrinklepipe.suffixes",
            "wrinklepipe.names",
            "wrinklepipe.errors",
            "wrinklepipe.asset",
            "wrinklepipe.metadata",
            "wrinklepipe.model",
            "wrinklepipe.codec",
            "wrinklepipe.metrics",
            "wrinklepipe.presets",
            "wrinklepipe.atomic",
            "wrinklepipe.staging",
            "wrinklepipe.console",
            "wrinklepipe.layers",
            "wrinklepipe.reuse",
            "wrinklepipe.workset",
            "wrinklepipe.arrayview",
            "wrinklepipe.package",
            "wrinklepipe.options",
            "wrinklepipe.palette",
            "wrinklepipe.udim",
        ),
    ),
    Layer(
        "files",
        "plain file helpers: pixels (OpenImageIO), PNG bytes, guarded JSON, confined paths, "
        "USD's diagnostics captured, the Khronos validator",
        ("wrinklepipe.io",),
    ),
    Layer(
        "stages",
        "array-in, array-out stages: geometry, normal maps, colour maps, masks, weight drivers, "
        "shader generation, fidelity, capture",
        (
            "wrinklepipe.geometry",
            "wrinklepipe.normals",
            "wrinklepipe.color",
            "wrinklepipe.masks",
            "wrinklepipe.drivers",
            "wrinklepipe.shading",
            "wrinklepipe.fidelity",
            "wrinklepipe.capture",
        ),
    ),
    Layer(
        "formats",
        "readers and writers of whole formats: the glTF document and packages, USD stages "
        "and packages, the reader table and mesh ingest (OBJ)",
        (
            "wrinklepipe.gltf",
            "wrinklepipe.usd",
            "wrinklepipe.readers",
        ),
    ),
    Layer(
        "pipeline",
        "convert's stages on an asset, what convert writes, engine export files, the demo",
        (
            "wrinklepipe.pipeline",
            "wrinklepipe.outputs",
            "wrinklepipe.export",
            "wrinklepipe.demo",
        ),
    ),
    Layer(
        "validate",
        "the validator: rules and the render pass over a validation input",
        ("wrinklepipe.validate",),
    ),
    Layer(
        "sources",
        "the source manifest; a manifest, an output folder or a file -> pipeline or "
        "validation inputs",
        ("wrinklepipe.sources",),
    ),
    Layer(
        "jobs",
        "whole runs that read, run stages, validate and write a folder; the viewer's server",
        (
            "wrinklepipe.jobs",
            "wrinklepipe.batch",
            "wrinklepipe.view",
        ),
    ),
    Layer(
        "cli",
        "the command line (one thin module per command), the benchmarks, the reference pages",
        (
            "wrinklepipe.cli",
            "wrinklepipe.__main__",
            "wrinklepipe.commands",
            "wrinklepipe.bench",
            "wrinklepipe.reference",
        ),
    ),
)


def layer_of(module: str) -> Layer:
    """The layer holding ``module`` (longest matching prefix). KeyError when none does."""
    best: tuple[int, Layer] | None = None
    for layer in LAYERS:
        for p in layer.prefixes:
            # the root package holds only itself: a new subpackage must be placed on purpose
            if module == p or (p != "wrinklepipe" and module.startswith(p + ".")):
                if best is None or len(p) > best[0]:
                    best = (len(p), layer)
    if best is None:
        raise KeyError(module)
    return best[1]


def rank(module: str) -> int:
    """Position of ``module``'s layer in :data:`LAYERS` (0 = core)."""
    return LAYERS.index(layer_of(module))


def may_import(importer: str, imported: str) -> bool:
    """True when ``importer`` may import ``imported``: same layer or a layer below."""
    return rank(imported) <= rank(importer)


def markdown_table() -> str:
    """The table of ``docs/architecture.md`` (between its ``layers`` markers)."""
    rows = [
        "| # | layer | holds | modules | may import |",
        "|---|---|---|---|---|",
    ]
    for i, layer in enumerate(LAYERS):
        mods = ", ".join(f"`{p.removeprefix('wrinklepipe.')}`" for p in layer.prefixes)
        below = ", ".join(x.name for x in LAYERS[:i]) or "(nothing else)"
        rows.append(f"| {i} | **{layer.name}** | {layer.holds} | {mods} | {below} |")
    return "\n".join(rows) + "\n"


if __name__ == "__main__":  # pragma: no cover - prints the docs table
    print(markdown_table(), end="")
