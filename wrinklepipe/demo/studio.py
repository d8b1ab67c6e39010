"""A small studio repository of demo characters, for ``wrinklepipe batch`` tests and benchmarks.

``write_studio(folder, sizes)`` writes variants of the demo head (different map sizes,
encodings and policies) as the source files an artist hands over, in a folder tree the way a
studio keeps characters::

    chars/ada/manifest.toml     pd, clamp01 (the demo as it is)
    chars/bo/manifest.toml      pd, signed (Oat: stretch and compress on one weight)
    chars/cy/manifest.toml      diff, clamp01
    chars/di/manifest.toml      full, additive (MetaHuman style)
    chars/ed/manifest.toml      composite, renormalize
    chars/fay/manifest.toml     pd, lerp (Reis)
    npc/gus/manifest.toml       pd, renormalize
    npc/hal/lod1.toml           pd, clamp01, the jimenez8 mask layout (a second manifest name)

Variant ``i`` has map size ``sizes[i % len(sizes)]``.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

from wrinklepipe.demo.source import write_demo_source
from wrinklepipe.presets import jimenez

#: (manifest path, encoding, policy, mask layout or None)
VARIANTS: tuple[tuple[str, str, str, str | None], ...] = (
    ("chars/ada/manifest.toml", "pd", "clamp01", None),
    ("chars/bo/manifest.toml", "pd", "signed", None),
    ("chars/cy/manifest.toml", "diff", "clamp01", None),
    ("chars/di/manifest.toml", "full", "additive", None),
    ("chars/ed/manifest.toml", "composite", "renormalize", None),
    ("chars/fay/manifest.toml", "pd", "lerp", None),
    ("npc/gus/manifest.toml", "pd", "renormalize", None),
    ("npc/hal/lod1.toml", "pd", "clamp01", "jimenez8"),
)


#: Policies whose weights lie in [0, 1]: Table 1.1's negative weights are left out for them.
_NON_NEGATIVE = ("renormalize", "lerp")


def _non_negative_table() -> str:
    lines = []
    for expr, row in jimenez.expression_table().items():
        lines.append(f"[expressions.{expr}]")
        lines += [f"{region} = {max(float(w), 0.0)}" for region, w in row.items()]
        lines.append("")
    return "\n".join(lines)


def variant_text(text: str, name: str, encoding: str, policy: str, layout: str | None) -> str:
    """The demo manifest with another name, encoding, policy and mask layout."""
    if policy in _NON_NEGATIVE:
        text = text.replace('expressions = "jimenez"\n', "", 1)
        text += "\n# Table 1.1 without its negative weights (this policy's weights lie in [0, 1])\n"
        text += _non_negative_table()
    text = re.sub(r'^name = ".*"$', f'name = "{name}"', text, count=1, flags=re.M)
    text = re.sub(r'^encoding = ".*"$', f'encoding = "{encoding}"', text, count=1, flags=re.M)
    text = re.sub(r'^policy = ".*"$', f'policy = "{policy}"', text, count=1, flags=re.M)
    if layout:
        text += f'\n[formats]\nmask_layout = "{layout}"\n'
    return text


def write_studio(
    folder: str | Path, sizes: Sequence[int] | int = 64, count: int | None = None
) -> list[Path]:
    """Write the :data:`VARIANTS` (the first ``count`` of them) under ``folder``; return their
    manifest paths."""
    folder = Path(folder)
    sizes = [sizes] if isinstance(sizes, int) else list(sizes)
    out = []
    for i, (rel, encoding, policy, layout) in enumerate(VARIANTS[:count]):
        target = folder / rel
        written = write_demo_source(target.parent, sizes[i % len(sizes)])
        name = target.parent.name + ("_" + target.stem if target.stem != "manifest" else "")
        text = variant_text(written.read_text(encoding="utf-8"), name, encoding, policy, layout)
        if written != target:
            written.unlink()
        target.write_text(text, encoding="utf-8")
        out.append(target)
    return out
