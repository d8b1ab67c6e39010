"""Block formats by fidelity for the stored maps of any encoding (diff, full, composite too).

The searches of :mod:`.search` make PD states themselves; an asset of another encoding ships
its maps at the manifest's sizes, and only the block formats of its compressed copies are
automatic. They are chosen here by the one measure (:mod:`.metric`), inside each pose's active
region against the full-resolution source, never over the whole map (where most texels are
flat): each candidate is the stored 8-bit texels (what the PNGs hold) through the block format
and back (the encoder the copies use, decoded by texture2ddecoder), decoded by the codec the
way the validator decodes a shipped texture. States first (smallest blocks first; the base as
shipped), then the base with the chosen states (its own error over the face within the budget
too), then the pair confirmed on every active texel; a pair over the budget there is not
shipped (the base, then the states fall back to PNG only), so the validator never finds the
automatic choice over its budget.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wrinklepipe import codec
from wrinklepipe.fidelity import metric as fm
from wrinklepipe.fidelity import reference as fre
from wrinklepipe.fidelity import sampling as fsa
from wrinklepipe.fidelity import ship
from wrinklepipe.fidelity.judge import Candidate, Judge, Tried, pick_format
from wrinklepipe.metrics import Budget
from wrinklepipe.normals import compress as nc


@dataclass
class FormatChoice:
    """The block formats chosen (``"png"``: no copy), the candidates tried, the confirmed
    fidelity of the compressed pair (None when nothing is compressed)."""

    base_format: str
    state_format: str
    compressed: fm.Fidelity | None
    budget: Budget
    tried: list[Tried] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {
            "base_format": self.base_format,
            "state_format": self.state_format,
            "compressed_budget": {
                k: v
                for k, v in (
                    ("max_mean_deg", self.budget.mean),
                    ("max_p99_deg", self.budget.p99),
                    ("max_max_deg", self.budget.max),
                )
                if v is not None
            },
            "compressed": None if self.compressed is None else self.compressed.to_json(),
            "tried": [t.to_json() for t in self.tried],
            "notes": self.notes,
        }


def roundtrip(texels: np.ndarray, fmt: str) -> np.ndarray:
    """8-bit texels ``[H, W, C]`` (C = 2 or 3: the components ``fmt`` stores) through block
    format ``fmt`` and back: the whole map encoded as its copy is (the same encoder call, so
    the copy's is a hit of the run's memo), decoded by texture2ddecoder."""
    q = np.ascontiguousarray(texels, np.uint8)
    h, w, c = q.shape
    qp, _ = nc.pad_to_blocks(q)
    hp, wp = qp.shape[:2]
    data = nc.encode_bc(nc.pack_rgba(qp, fmt), fmt)
    return np.ascontiguousarray(nc.unpack_u8(nc.decode_bc(data, wp, hp, fmt), fmt, c)[:h, :w])


def stored_components(texels: np.ndarray, encoding: str, fmt: str | None) -> np.ndarray:
    """The components of stored texels a format keeps (x, y and z where its layout stores z;
    ``fmt`` None: the PNG, every component of the encoding)."""
    e = codec.encoding(encoding)
    if fmt is None:
        return np.asarray(texels)[..., : e.components]
    lay = codec.storage_format(fmt).layout_for(encoding)
    return np.asarray(texels)[..., : 3 if lay.stores_z else 2]


def decode_stored(q: np.ndarray, encoding: str, param: float, version: int) -> np.ndarray:
    """Stored 8-bit components -> what :func:`wrinklepipe.model.combine` takes (``"base"``:
    unit normals), exactly as the validator decodes a shipped texture (two components: z
    rebuilt)."""
    e = codec.encoding("full" if encoding == "base" else encoding)
    where = "rgb" if q.shape[-1] == 3 else "rg"
    return e.combine_input(codec.decode(e, q, where, param=param, version=version))


@fsa.one_blas_thread
def choose_formats(
    ref: fre.Reference,
    base_texels: np.ndarray,
    state_texels: Sequence[np.ndarray],
    masks: np.ndarray,
    encoding: str,
    param: float,
    version: int,
    budget: Budget,
    fixed_base: str | None = None,
    fixed_states: str | None = None,
    formats: Sequence[str] = ship.BLOCK_FORMATS,
    screen_texels: int = 60_000,
) -> FormatChoice:
    """The block formats of the base and the states by fidelity (module doc).

    ``ref``: the full-resolution source prepared in ``encoding``; ``base_texels`` ``[h, w, 3]``
    and ``state_texels`` ``[hs, ws, C]``: the stored 8-bit texels (the PNGs); ``masks``: the
    shipped mask values. ``fixed_*``: a format the manifest fixes (measured, not chosen;
    ``"png"``: no copy). ``formats``: tried smallest blocks first, those that can hold the
    encoding."""
    judge = Judge(ref, screen_texels)
    tried: list[Tried] = []
    notes: list[str] = []
    base_png = decode_stored(stored_components(base_texels, "full", None), "base", 1.0, 1)
    states_png = np.stack(
        [
            decode_stored(stored_components(q, encoding, None), encoding, param, version)
            for q in state_texels
        ]
    )
    judge.set("base", lambda r: {"base": base_png})
    judge.set("masks", lambda r: {"masks": masks})
    judge.set("states", lambda r: {"states": states_png})
    face = ref.face_texels()
    made: dict[tuple[str, str], Candidate] = {}  # one candidate per format: the judge keys by id

    def states_in(f: str) -> Candidate:
        if ("states", f) not in made:
            got = [
                decode_stored(
                    roundtrip(stored_components(q, encoding, f), f), encoding, param, version
                )
                for q in state_texels
            ]
            arrays = {"states": np.stack(got)}
            made[("states", f)] = lambda r: arrays
        return made[("states", f)]

    def base_in(f: str) -> Candidate:
        if ("base", f) not in made:
            q = roundtrip(stored_components(base_texels, "full", f), f)
            arrays = {"base": decode_stored(q, "base", 1.0, 1)}
            made[("base", f)] = lambda r: arrays
        return made[("base", f)]

    state_fmts = [f for f in formats if codec.storage_format(f).holds(encoding)]
    base_fmts = [f for f in formats if codec.storage_format(f).holds("full")]
    state_fmt = pick_format(
        judge, fixed_states, state_fmts, budget, tried, "state format", states_in
    )
    if state_fmt != "png":
        judge.set("states", states_in(state_fmt))
    base_fmt = pick_format(
        judge,
        fixed_base,
        base_fmts,
        budget,
        tried,
        "base format",
        base_in,
        alone=lambda make: fm.base_fidelity(ref, make(ref)["base"], face),
    )
    if base_fmt != "png":
        judge.set("base", base_in(base_fmt))
    automatic = {"base": fixed_base in (None, "auto"), "states": fixed_states in (None, "auto")}
    compressed = None
    while state_fmt != "png" or base_fmt != "png":
        compressed = judge.run(True)
        tried.append(
            Tried(
                "confirmed (compressed)",
                [state_fmt, base_fmt],
                *compressed.score(),
                compressed.inside(budget),
            )
        )
        # over the budget on every active texel: an automatic base, then automatic states
        # ship as PNG only (a format the manifest fixes is measured, not dropped)
        over = [
            g for g, f in (("base", base_fmt), ("states", state_fmt)) if f != "png" and automatic[g]
        ]
        if compressed.inside(budget) or not over:
            break
        what = over[0]
        notes.append(
            f"{what} {base_fmt if what == 'base' else state_fmt}: over the budget "
            f"({budget.describe()} degrees) on every active texel (worst "
            f"{compressed.worst.pose} p99 {compressed.worst.overall.p99:.2f}); PNG only"
        )
        if what == "base":
            base_fmt = "png"
            judge.set("base", lambda r: {"base": base_png})
        else:
            state_fmt = "png"
            judge.set("states", lambda r: {"states": states_png})
        compressed = None
    if compressed is not None:
        compressed.base = fm.base_fidelity(ref, judge.full("base").raw["base"], face)
    return FormatChoice(base_fmt, state_fmt, compressed, budget, tried, notes)


__all__ = ["FormatChoice", "choose_formats", "decode_stored", "roundtrip", "stored_components"]
