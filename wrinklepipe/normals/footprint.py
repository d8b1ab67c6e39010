"""Texture memory footprint, side by side with the paper's setup.

Jimenez et al. (GPU Pro 2): one 256 x 256 BC5 (3Dc) wrinkle map plus two 64 x 64 RGBA8 masks
= 65 536 + 2 x 16 384 = 98 304 bytes = 96 KB (no mips).
"""

from __future__ import annotations

from dataclasses import dataclass, field

#: Bytes per 4x4 block of the block formats; bytes per texel of the plain ones.
BLOCK_BYTES = {"bc1": 8, "bc3": 16, "bc3nm": 16, "bc5": 16, "bc7": 16}
TEXEL_BYTES = {"r8": 1, "rg8": 2, "rgb8": 3, "rgba8": 4, "rg16": 4, "rgb16": 6, "rgba16": 8}

#: (name, format, width, height) of the paper's wrinkle setup.
PAPER_SETUP: tuple[tuple[str, str, int, int], ...] = (
    ("wrinkle map (PD, 3Dc)", "bc5", 256, 256),
    ("mask 1 (RGBA8)", "rgba8", 64, 64),
    ("mask 2 (RGBA8)", "rgba8", 64, 64),
)


def texture_bytes(fmt: str, width: int, height: int, mips: bool = False) -> int:
    """Bytes of a texture (all mip levels down to 1 x 1 when ``mips``)."""
    total = 0
    w, h = width, height
    while True:
        if fmt in BLOCK_BYTES:
            total += ((w + 3) // 4) * ((h + 3) // 4) * BLOCK_BYTES[fmt]
        elif fmt in TEXEL_BYTES:
            total += w * h * TEXEL_BYTES[fmt]
        else:
            raise ValueError(f"unknown texture format {fmt!r}")
        if not mips or (w == 1 and h == 1):
            return total
        w, h = max(1, w // 2), max(1, h // 2)


def paper_total() -> int:
    """The paper's setup in bytes (98 304 = 96 KB)."""
    return sum(texture_bytes(f, w, h) for _, f, w, h in PAPER_SETUP)


@dataclass
class Footprint:
    """Rows of (name, format, width, height, mips, bytes), the total and the paper's total."""

    rows: list[dict[str, object]] = field(default_factory=list)
    total: int = 0
    paper_total: int = 0

    def to_json(self) -> dict[str, object]:
        return {
            "rows": self.rows,
            "total_bytes": self.total,
            "total_kb": round(self.total / 1024, 3),
            "paper_total_bytes": self.paper_total,
            "paper_total_kb": round(self.paper_total / 1024, 3),
            "ratio_to_paper": round(self.total / self.paper_total, 4) if self.paper_total else None,
            "paper_rows": [
                {"name": n, "format": f, "width": w, "height": h, "bytes": texture_bytes(f, w, h)}
                for n, f, w, h in PAPER_SETUP
            ],
        }


def footprint(entries: list[tuple[str, str, int, int, bool]]) -> Footprint:
    """Footprint of ``(name, format, width, height, mips)`` textures against the paper's 96 KB."""
    rows = []
    for name, fmt, w, h, mips in entries:
        rows.append(
            {
                "name": name,
                "format": fmt,
                "width": w,
                "height": h,
                "mips": mips,
                "bytes": texture_bytes(fmt, w, h, mips),
            }
        )
    total = sum(int(r["bytes"]) for r in rows)
    return Footprint(rows, total, paper_total())
