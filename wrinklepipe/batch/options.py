"""What one asset of a batch is converted with: ``convert``'s options plus the PNG level and the
severity that fails it. Batch files set them for every asset (``[defaults]``) and per asset
(``[[assets]]``); the command line sets the defaults.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace
from typing import Any

from wrinklepipe.io.png import DEFAULT_PNG_LEVEL
from wrinklepipe.jobs.convert import ConvertOptions
from wrinklepipe.masks.layouts import LAYOUTS
from wrinklepipe.names import noun
from wrinklepipe.validate.catalogue import SEVERITIES

USD_FORMATS = ("usda", "usdc", "usdz")
MASK_LAYOUTS = LAYOUTS  # masks.layouts: the packing layouts
FAIL_ON = SEVERITIES  # validate.catalogue: a severity fails an asset


@dataclass(frozen=True)
class AssetOptions:
    """Options of one asset. All but ``fail_on`` change the output bytes (so the cache key);
    ``fail_on`` only decides which validation issues fail the asset."""

    glb: bool = False
    usd: str = "usda"
    compress: bool = True
    validate: bool = True
    render: bool = True
    bits: int = 8
    mask_layout: str | None = None
    png_level: int = DEFAULT_PNG_LEVEL
    fail_on: str = "error"

    def convert_options(self, force: bool) -> ConvertOptions:
        """The :class:`ConvertOptions` ``convert`` runs with."""
        return ConvertOptions(
            glb=self.glb,
            usd_format=self.usd,
            force=force,
            compressed=self.compress,
            validate=self.validate,
            render=self.render,
            bits=self.bits,
            mask_layout=self.mask_layout,
            png_level=self.png_level,
        )

    def output_fields(self) -> dict[str, Any]:
        """The options that decide the output bytes (part of the cache key)."""
        out = asdict(self)
        out.pop("fail_on")
        return out

    def updated(self, values: dict[str, Any]) -> AssetOptions:
        """A copy with ``values`` (batch-file keys, already schema-checked) applied."""
        known = {f.name for f in fields(self)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise KeyError(f"unknown {noun(len(unknown), 'option')} {unknown}")
        return replace(self, **values)


#: The batch-file keys that are options (the rest of an ``[[assets]]`` table says which manifest
#: and where): the schema (``schemas/batch.schema.json``) lists the same.
OPTION_KEYS = tuple(f.name for f in fields(AssetOptions))
