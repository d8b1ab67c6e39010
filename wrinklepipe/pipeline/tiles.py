"""The stages on UDIM tiles: each tile on its own, then one choice for all.

Each tile is an ordinary asset (:mod:`wrinklepipe.pipeline.ingest_tiles`) and runs the
stages on its own (:func:`wrinklepipe.pipeline.prepare.run_stages`: resampling and, for pd,
the automatic choices by fidelity against the tile's source). What one material says for
every tile must then agree: the PD scale (a shader constant), and, so that one UDIM texture
set has one size and one block format per map, the states' and masks' sizes and the block
formats. The joint choice is what the most demanding tile chose: the largest scale, the
largest sizes, the format furthest along ``bc1 < bc5 < bc3nm < bc7 < bc7xy < png`` (no
copy); every tile whose own choice differs is measured again at the joint one (the fixed
choices the searches then measure, not search), so each tile's reported fidelity is that of
what ships.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

from wrinklepipe import fidelity as fd
from wrinklepipe.asset import WrinkleAsset
from wrinklepipe.names import noun
from wrinklepipe.options import FormatOptions
from wrinklepipe.pipeline.prepare import StageReport, run_stages

#: Block formats from the least to the most precise (``png8``: no copy, the PNG ships).
FORMAT_ORDER: tuple[str, ...] = ("bc1", "bc5", "bc3nm", "bc7", "bc7xy", "uastc", "png8")


@dataclass
class TileStages:
    """Every tile's asset after the stages and its report, with the joint choice's notes."""

    assets: dict[int, WrinkleAsset]
    reports: dict[int, StageReport]
    notes: list[str] = field(default_factory=list)

    @property
    def formats(self) -> dict[str, str]:
        """The block formats of the copies (every tile's: the joint choice)."""
        first = self.reports[min(self.reports)]
        return dict(first.formats)

    def fidelity(self) -> dict[str, object] | None:
        """The choices' record per tile (report.json), None when no search ran."""
        got = {str(t): r.fidelity for t, r in self.reports.items() if r.fidelity is not None}
        return {"tiles": got} if got else None


def strongest(formats: Sequence[str]) -> str:
    """The most precise of the formats (the furthest along :data:`FORMAT_ORDER`; one not
    listed wins over those listed)."""
    rank = {f: i for i, f in enumerate(FORMAT_ORDER)}
    return max(formats, key=lambda f: rank.get(f, len(FORMAT_ORDER)))


def _choices(asset: WrinkleAsset, rep: StageReport) -> dict[str, object]:
    return {
        "pd_scale": float(asset.pd_scale),
        "wrinkle": int(asset.states.shape[1]),
        "mask": int(asset.masks.shape[1]),
        **{f"format_{k}": v for k, v in sorted(rep.formats.items())},
    }


def run_tile_stages(
    tiles: dict[int, WrinkleAsset],
    auto_scale: bool,
    formats: FormatOptions | None = None,
    compressed: bool = True,
    poses: Sequence[fd.Pose] | None = None,
) -> TileStages:
    """:func:`run_stages` on every tile, then the joint choice (module doc) measured on every
    tile whose own choice differs."""
    formats = formats or FormatOptions()
    got = {
        t: run_stages(a, auto_scale=auto_scale, formats=formats, compressed=compressed, poses=poses)
        for t, a in tiles.items()
    }
    own = {t: _choices(a, r) for t, (a, r) in got.items()}
    joint = {
        "pd_scale": max(float(c["pd_scale"]) for c in own.values()),
        "wrinkle": max(int(c["wrinkle"]) for c in own.values()),  # type: ignore[call-overload]
        "mask": max(int(c["mask"]) for c in own.values()),  # type: ignore[call-overload]
    }
    for key in sorted({k for c in own.values() for k in c if k.startswith("format_")}):
        joint[key] = strongest([str(c[key]) for c in own.values() if key in c])
    notes = []
    redo = [t for t, c in own.items() if c != joint]
    if redo:
        said = ", ".join(
            f"{k.removeprefix('format_')} {joint[k]}"
            for k in joint
            if len({str(c.get(k)) for c in own.values()}) > 1
        )
        notes.append(
            f"UDIM: the tiles chose differently ({said} for all: what the most demanding tile "
            f"needs); {noun(len(redo), 'tile')} {', '.join(map(str, redo))} measured again at "
            "that choice"
        )
    fixed_formats = replace(
        formats,
        **{k.removeprefix("format_"): str(v) for k, v in joint.items() if k.startswith("format_")},
    )
    for t in redo:
        src = tiles[t]
        prov = {**src.provenance, "auto_resolution": []}
        res = {**src.resolution, "wrinkle": int(joint["wrinkle"]), "mask": int(joint["mask"])}
        fixed = replace(src, pd_scale=float(joint["pd_scale"]), resolution=res, provenance=prov)
        got[t] = run_stages(
            fixed, auto_scale=False, formats=fixed_formats, compressed=compressed, poses=poses
        )
        rep = got[t][1]
        if auto_scale:
            rep.pd_scale_source = "auto (the largest any UDIM tile needs)"
    return TileStages(
        {t: a for t, (a, _) in got.items()}, {t: r for t, (_, r) in got.items()}, notes
    )
