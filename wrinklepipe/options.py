"""A manifest's options, typed and declared once: ``[budget]`` as :class:`BudgetOptions`,
``[formats]`` as :class:`FormatOptions`, ``[resolution]`` as :class:`ResolutionOptions`.

The defaults are the manifest schema's (``schemas/manifest.schema.json``: each key's
``default``), read once here. The manifest loader builds the options from the manifest's table
(:meth:`BudgetOptions.from_json`); the automatic choices (:mod:`wrinklepipe.pipeline.auto`),
the compressed copies (:mod:`wrinklepipe.normals.copies`) and the validator's rules take them
typed and ask the same two questions: :meth:`BudgetOptions.maps` (the budget of the maps as
shipped in PNG) and :meth:`BudgetOptions.copies` (of the block-compressed copies). So a map
chosen inside the budget is judged by the same budget wherever it is checked.

A budget key the manifest leaves out takes the schema's default (``max_mean_deg`` 0.5,
``max_p99_deg`` 2.0, ``max_max_deg`` none; the colour states' ``max_mean_delta_e`` 1.0 and
``max_p99_delta_e`` 2.3, :meth:`BudgetOptions.color`); the ``compressed_`` keys default to the
maps' budget. A new statistic is one more key in the schema with its ``default`` and one more
field here.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, fields
from typing import Any

from wrinklepipe.metrics import Budget
from wrinklepipe.paths import SCHEMAS_DIR

_SCHEMA: dict[str, Any] = json.loads(
    (SCHEMAS_DIR / "manifest.schema.json").read_text(encoding="utf-8")
)["properties"]
#: The ``[budget]`` properties of the manifest schema (types, bounds, defaults).
BUDGET_SCHEMA: dict[str, Any] = _SCHEMA["budget"]["properties"]
#: The ``[formats]`` properties (the formats each map kind may be stored in, defaults).
FORMATS_SCHEMA: dict[str, Any] = _SCHEMA["formats"]["properties"]
#: The ``[resolution]`` properties (the sizes each map kind may ship at).
RESOLUTION_SCHEMA: dict[str, Any] = _SCHEMA["resolution"]["properties"]
#: The value of a ``[resolution]`` key that asks for the size to be chosen by fidelity.
AUTO = "auto"


def _default(key: str) -> float | None:
    value = BUDGET_SCHEMA[key].get("default")
    return None if value is None else float(value)


#: The maps' budget when the manifest gives none of its keys: the schema's defaults.
DEFAULT_MAX_MEAN_DEG = _default("max_mean_deg")
DEFAULT_MAX_P99_DEG = _default("max_p99_deg")
DEFAULT_MAX_MAX_DEG = _default("max_max_deg")
#: The colour budget's (CIEDE2000 inside each pose's active region, colour states only).
DEFAULT_MAX_MEAN_DELTA_E = _default("max_mean_delta_e")
DEFAULT_MAX_P99_DELTA_E = _default("max_p99_delta_e")


@dataclass(frozen=True)
class BudgetOptions:
    """A manifest's ``[budget]`` as given (None: left out; the defaults apply in
    :meth:`maps` and :meth:`copies`). Field names are the manifest's keys."""

    max_mean_deg: float | None = None
    max_p99_deg: float | None = None
    max_max_deg: float | None = None
    max_bytes: int | None = None
    compressed_max_mean_deg: float | None = None
    compressed_max_p99_deg: float | None = None
    compressed_max_max_deg: float | None = None
    max_mean_delta_e: float | None = None
    max_p99_delta_e: float | None = None

    @classmethod
    def from_json(cls, table: dict[str, Any] | None) -> BudgetOptions:
        """From a manifest's ``[budget]`` table (already checked by the schema: known keys,
        numbers); ``max_bytes`` as an integer, the rest as floats."""
        table = table or {}
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(table) - known)
        if unknown:
            raise ValueError(f"unknown budget keys {unknown}")
        return cls(**{k: (int(v) if k == "max_bytes" else float(v)) for k, v in table.items()})

    def to_json(self) -> dict[str, float | int]:
        """The keys the manifest gave (sorted), as it gave them."""
        return {
            f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not None
        }

    @property
    def given(self) -> bool:
        """True when the manifest gave any budget key."""
        return bool(self.to_json())

    @property
    def compressed_given(self) -> bool:
        """True when the manifest gave a ``compressed_max_*`` key."""
        return any(
            v is not None
            for v in (
                self.compressed_max_mean_deg,
                self.compressed_max_p99_deg,
                self.compressed_max_max_deg,
            )
        )

    def maps(self) -> Budget:
        """The budget of the maps (PNG): each statistic the manifest's, else the schema's
        default."""
        return Budget(
            DEFAULT_MAX_MEAN_DEG if self.max_mean_deg is None else self.max_mean_deg,
            DEFAULT_MAX_P99_DEG if self.max_p99_deg is None else self.max_p99_deg,
            DEFAULT_MAX_MAX_DEG if self.max_max_deg is None else self.max_max_deg,
        )

    def color(self) -> Budget:
        """The colour budget (ΔE00) of the colour states: each statistic the manifest's, else
        the schema's default."""
        return Budget(
            DEFAULT_MAX_MEAN_DELTA_E if self.max_mean_delta_e is None else self.max_mean_delta_e,
            DEFAULT_MAX_P99_DELTA_E if self.max_p99_delta_e is None else self.max_p99_delta_e,
            None,
        )

    def copies(self) -> Budget:
        """The budget of the block-compressed copies: the ``compressed_max_*`` keys when the
        manifest gives any (the others unlimited), else the maps' budget."""
        if not self.compressed_given:
            return self.maps()
        return Budget(
            self.compressed_max_mean_deg, self.compressed_max_p99_deg, self.compressed_max_max_deg
        )


@dataclass(frozen=True)
class FormatOptions:
    """A manifest's ``[formats]``: the storage format of the base, the wrinkle states, the masks
    and the colour states (``"auto"``: chosen by fidelity within the budget) and the mask
    layout. Each field defaults to the schema's ``default``."""

    base: str = str(FORMATS_SCHEMA["base"]["default"])
    wrinkle: str = str(FORMATS_SCHEMA["wrinkle"]["default"])
    mask: str = str(FORMATS_SCHEMA["mask"]["default"])
    mask_layout: str = str(FORMATS_SCHEMA["mask_layout"]["default"])
    color: str = str(FORMATS_SCHEMA["color"]["default"])

    @classmethod
    def from_json(cls, table: dict[str, Any] | None) -> FormatOptions:
        """From a manifest's ``[formats]`` table (already checked by the schema)."""
        table = table or {}
        unknown = sorted(set(table) - {f.name for f in fields(cls)})
        if unknown:
            raise ValueError(f"unknown formats keys {unknown}")
        return cls(**{k: str(v) for k, v in table.items()})

    def to_json(self) -> dict[str, str]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class ResolutionOptions:
    """A manifest's ``[resolution]``: the size (texels, square) the base, the wrinkle states, the
    masks and the colour states ship at; ``"auto"`` (not the base): the smallest size whose
    fidelity meets the budget; None (left out): the source's own size."""

    base: int | None = None
    wrinkle: int | str | None = None
    mask: int | str | None = None
    color: int | str | None = None

    @classmethod
    def from_json(cls, table: dict[str, Any] | None) -> ResolutionOptions:
        """From a manifest's ``[resolution]`` table (already checked by the schema)."""
        table = table or {}
        unknown = sorted(set(table) - {f.name for f in fields(cls)})
        if unknown:
            raise ValueError(f"unknown resolution keys {unknown}")
        return cls(**{k: (v if v == AUTO else int(v)) for k, v in table.items()})

    def to_json(self) -> dict[str, int | str]:
        """The keys the manifest gave, as it gave them."""
        return {
            f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not None
        }

    def sizes(self) -> dict[str, int]:
        """The sizes the manifest fixes (``{kind: texels}``; neither ``auto`` nor left out)."""
        return {k: v for k, v in self.to_json().items() if isinstance(v, int)}

    def automatic(self) -> list[str]:
        """The kinds whose size is chosen by fidelity (``"auto"``), sorted."""
        return sorted(k for k, v in self.to_json().items() if v == AUTO)
