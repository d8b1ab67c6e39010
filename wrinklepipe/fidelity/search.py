"""Automatic choices by fidelity: state size, mask size, PD scale, block formats.

Every candidate is what convert would write (:mod:`.ship`), decoded, and judged by the one
measure (:mod:`.metric`) against the full-resolution source, inside each pose's active
region. The searches share their work:

- the source is prepared once (:func:`~wrinklepipe.fidelity.reference.prepare`: the one
  full-resolution pass over the masks and the poses);
- every state size comes from one Lanczos-3 pyramid (:mod:`.pyramid`), which is also what
  convert ships;
- candidates are screened on a coarse subset of the active texels
  (:meth:`~wrinklepipe.fidelity.reference.Reference.coarse`) and only the one that passes is
  confirmed on all of them; samples of what a step does not change are kept.

Order (each step with the choices made so far): a provisional PD scale at full size, the
smallest state size that meets the budget, the PD scale at that size (the one with the least
error, clipping included: the tool never fails its own choice), the smallest mask size that
meets the budget, then the block formats (smallest blocks first) against the budget of the
compressed copies. A choice fixed in the manifest is measured, not searched.

Every candidate is judged inside the budget by :meth:`wrinklepipe.metrics.Budget.inside` (the
unrounded statistics), which the validator's verdict (:meth:`~wrinklepipe.metrics.Budget.ok`,
at the printed decimals) always accepts: a pick is half a printed unit inside what the
validator can reject. A block format whose screen passed but whose confirmation on every
active texel does not is not shipped: the next one is tried (the states' format first, then
the base's), down to no compressed copy.
"""

from __future__ import annotations

import gc
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wrinklepipe import reuse
from wrinklepipe.fidelity import metric as fm
from wrinklepipe.fidelity import pyramid, scales, ship
from wrinklepipe.fidelity import reference as fre
from wrinklepipe.fidelity import sampling as fsa
from wrinklepipe.fidelity.judge import (
    Candidate,
    Judge,
    Tried,
    _base_alone,
    _call,
    _factory,
    _RoundTrips,
    _smallest_passing,
    pick_format,
)
from wrinklepipe.fidelity.level import PdLevel
from wrinklepipe.fidelity.scales import clipped_texels, largest_held, scale_candidates
from wrinklepipe.metrics import Budget
from wrinklepipe.normals.encode import MAX_PD_SCALE
from wrinklepipe.normals.held import rows_of

_F = np.float32

#: Fractions of the largest active slope tried as PD scales (1: nothing clips).
SCALE_FACTORS: tuple[float, ...] = (1.0, 0.875, 0.75)


@dataclass(frozen=True)
class SearchOptions:
    """``min_size`` / ``min_mask_size``: the smallest sizes tried. ``formats``: block formats
    tried (smallest blocks first). ``screen_texels``: active texels a candidate is screened on
    before it is confirmed on all of them."""

    min_size: int = 16
    min_mask_size: int = 16
    formats: tuple[str, ...] = ship.BLOCK_FORMATS
    screen_texels: int = 60_000
    scale_factors: tuple[float, ...] = SCALE_FACTORS
    #: The validator's WP-MAP-004 limit: a state format whose copy puts more of a map's texels
    #: at the end of the range (than this fraction, and than the PNG) is not chosen.
    max_clipped_fraction: float = 0.001
    #: Maps of the format searches holding at most this many 4x4 blocks together are encoded
    #: whole, each format in one encoder pass (small assets: a pass costs tens of ms).
    whole_map_blocks: int = 4096


@dataclass
class Source:
    """What the pipeline read, at full resolution: the base as it will ship (unit normals, its
    own size), the wrinkle-only PD slopes ``[K, H, W, 2]`` on the source grid, the source masks
    ``[R, h, w]``, the poses, and the mesh's UV footprint on the grid."""

    base: np.ndarray
    slopes: np.ndarray
    masks: np.ndarray
    poses: Sequence[fre.Pose]
    region_names: Sequence[str]
    policy: str = "clamp01"
    footprint: np.ndarray | None = None
    source_base: np.ndarray | None = None  # the base on the grid, when ``base`` was resampled


@dataclass(frozen=True)
class Fixed:
    """Choices the manifest fixes (None: automatic). Formats: a block format, or ``"png"``."""

    wrinkle: int | None = None
    mask: int | None = None
    scale: float | None = None
    base_format: str | None = None
    state_format: str | None = None


@dataclass
class Choice:
    """What the searches chose, the candidates they tried and the final fidelity."""

    wrinkle_size: int
    mask_size: int
    pd_scale: float
    base_format: str  # a block format, or "png" (no compressed copy)
    state_format: str
    clipped_texels: list[int]  # per state: texels of the stored map whose slope was clipped
    png: fm.Fidelity
    compressed: fm.Fidelity | None
    states: np.ndarray  # [K, s, s, 2] the slopes to ship (from the pyramid)
    tried: list[Tried] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    budget: Budget = field(default_factory=Budget)
    compressed_budget: Budget = field(default_factory=Budget)

    def to_json(self) -> dict[str, Any]:
        return {
            "wrinkle": self.wrinkle_size,
            "mask": self.mask_size,
            "pd_scale": self.pd_scale,
            "base_format": self.base_format,
            "state_format": self.state_format,
            "clipped_texels": self.clipped_texels,
            "budget": self.budget.to_json(),
            "compressed_budget": self.compressed_budget.to_json(),
            "png": self.png.to_json(),
            "compressed": None if self.compressed is None else self.compressed.to_json(),
            "tried": [t.to_json() for t in self.tried],
            "notes": self.notes,
        }


# ------------------------------------------------------------------------------------------------
# candidates as decoded shipped data


# ------------------------------------------------------------------------------------------------
# the search


@fsa.one_blas_thread
def search(
    src: Source,
    budget: Budget,
    compressed_budget: Budget | None = None,
    fixed: Fixed | None = None,
    options: SearchOptions | None = None,
) -> Choice:
    """Choose state size, mask size, PD scale and block formats by fidelity (module doc)."""
    try:
        return _Search(src, budget, compressed_budget, fixed, options).run()
    finally:
        # what the search made (the slopes' pyramid, the mask levels, the base's texels, the
        # judge's samples: about twice the source states at full size) goes now: its candidate
        # factories and closures hold the search's objects in reference cycles, which only the
        # garbage collector frees, whenever it next runs
        gc.collect()


class _Search:
    """One run of :func:`search`: the source's reference, the shippable levels, the judge, and
    the steps of the module doc in order (each a method; what they share is kept here)."""

    def __init__(
        self,
        src: Source,
        budget: Budget,
        compressed_budget: Budget | None,
        fixed: Fixed | None,
        options: SearchOptions | None,
    ) -> None:
        o = self.o = options or SearchOptions()
        fx = self.fx = fixed or Fixed()
        self.src, self.budget = src, budget
        self.cbudget = compressed_budget or budget
        # a PdLevel (the full-size slopes made where they are read) stays one
        slopes = src.slopes if isinstance(src.slopes, PdLevel) else np.asarray(src.slopes, _F)
        self.slopes = slopes
        K, H, W = slopes.shape[:3]
        if H != W:
            raise ValueError(f"the searches need square state maps, got {W} x {H}")
        grid_base = src.source_base if src.source_base is not None else src.base
        if grid_base.shape[:2] != (H, W):
            raise ValueError("the source base must be given on the state grid (source_base)")
        self.H, self.grid_base = H, grid_base
        self.smallest = min(fx.wrinkle or o.min_size, H)
        # the source's full-resolution pass beside what the candidates are made from
        # (independent work, numpy's loops release the GIL: two threads when the thread budget
        # allows)
        ref, (base_texels, levels, mask_lv) = reuse.map_threads(
            _call, [self._reference, self._shippable]
        )
        self.ref, self.base_texels, self.levels, self.mask_lv = ref, base_texels, levels, mask_lv
        self.judge = judge = Judge(ref, o.screen_texels)
        self.tried: list[Tried] = []
        self.notes: list[str] = []
        png_base = {"base": base_texels, "base_reader": ship.base_reader("rgb")}
        self.png_base = png_base
        judge.set("base", lambda r: png_base)
        self.m0 = int(src.masks.shape[1])
        self.masks = _factory(self._masks)
        judge.set("masks", self.masks(self.m0))
        self.sizes = sorted(s for s in levels if s >= self.smallest)
        self.states = _factory(self._states)
        self.face = np.zeros(0, np.int64)
        # formats a screen passed but the confirmation on every active texel did not: not shipped
        self.refused: dict[str, set[str]] = {"state": set(), "base": set()}

    def _reference(self) -> fre.Reference:
        src = self.src
        return fre.prepare(
            rows_of(self.grid_base),  # held as integers: read at the texels used
            self.slopes,
            src.masks,
            src.poses,
            src.region_names,
            "pd",
            src.policy,
            src.footprint,
        )

    def _shippable(self) -> tuple[np.ndarray, dict[int, np.ndarray], ship.MaskLevels]:
        return (
            ship.base_texels(self.src.base),
            pyramid.levels(self.slopes, self.smallest),
            ship.mask_levels(self.src.masks, self.o.min_mask_size),
        )

    def _masks(self, m: int) -> Candidate:
        # the source's own masks cannot leak
        lv, m0 = self.mask_lv, self.m0
        return lambda r: {"masks": lv[m], "support": None if m != m0 else False}

    def _states(self, size: int, scale: float) -> Candidate:
        levels = self.levels
        return lambda r: {"states": levels[size], "states_reader": ship.pd_reader(scale)}

    def best_scale(self, size: int, label: str) -> float:
        """The PD scale of the states at ``size`` with the least error, clipping included."""
        o, judge, ref = self.o, self.judge, self.ref
        u = judge.coarse.union
        top = max(largest_held(fsa.sample_at(x, ref.shape, u)) for x in self.levels[size])
        # the validator's clipping rule (WP-MAP-004) counts every texel of the map, active or
        # not: a scale that clips more than it allows is never chosen, and the candidates
        # include the smallest scale that keeps every texel of the map inside the range
        limit = o.max_clipped_fraction * size * size
        level = self.levels[size]
        big = largest_held(level)
        safe = scale_candidates(big, (1.0,))[0]
        candidates = sorted({*scale_candidates(top, o.scale_factors), safe}, reverse=True)
        # only texels with a component above 0.99 of the smallest scale can reach the end of
        # the range (|t| >= 1 - 0.5/127): count clipping on that tail alone, as edge_texels does
        tails = scales.tails(level, candidates[-1])
        # texels that clip even at the largest scale (on or near the horizon: a two-channel
        # texel with x^2 + y^2 >= 1, a z = 0 normal) clip at every scale: counted as clipped in
        # the report and by the validator, never a reason to pick one scale over another
        lost = clipped_texels(tails, MAX_PD_SCALE)

        def clips(s: float) -> bool:
            return max((c - n for c, n in zip(clipped_texels(tails, s), lost)), default=0) > limit

        # the smallest scale that clips no more than the rule allows, in steps of 1/64 from the
        # largest |component| held, at most 64 steps (half an 8-bit step is 0.4 % of the range:
        # the first step past big / (1 - 0.5/127) clips nothing) and never past the largest
        for _ in range(64):
            if safe >= MAX_PD_SCALE or not clips(safe):
                break
            safe += 1.0 / 64.0
            candidates = sorted({*candidates, safe}, reverse=True)
        best: tuple[tuple[float, float], float] | None = None
        for s in candidates:
            if s < safe and clips(s):
                self.tried.append(Tried(f"{label} (clips, WP-MAP-004)", s, 0.0, 0.0, False))
                continue
            f = judge.run(False, self.states(size, s))
            self.tried.append(Tried(label, s, *f.score(), f.inside(self.budget), judge.screens))
            if best is None or f.score() < best[0]:
                best = (f.score(), s)
        assert best is not None  # the safe scale is always a candidate
        return best[1]

    def state_size(self, scale: float) -> int:
        """2. the state size: the smallest that meets the budget (screened)."""
        fx, H = self.fx, self.H
        if fx.wrinkle is not None:
            size = fx.wrinkle if fx.wrinkle in self.levels else H
            if size != fx.wrinkle:
                self.notes.append(f"wrinkle size {fx.wrinkle} is not a halving of {H}: kept {H}")
            return size
        judge, tried, budget = self.judge, self.tried, self.budget
        return (
            _smallest_passing(
                self.sizes,
                lambda s: judge.screen(budget, tried, "wrinkle", s, self.states(s, scale)),
            )
            or H
        )

    def mask_size(self) -> int:
        """4. the mask size: the smallest that meets the budget (screened)."""
        fx, m0 = self.fx, self.m0
        mask_size = fx.mask if fx.mask in self.mask_lv else m0
        if fx.mask is None:
            judge, tried, budget = self.judge, self.tried, self.budget
            smaller = sorted(m for m in self.mask_lv if m < m0)
            mask_size = (
                _smallest_passing(
                    smaller, lambda m: judge.screen(budget, tried, "mask", m, self.masks(m))
                )
                or m0
            )
        return mask_size

    def formats(self, size: int, scale: float) -> _Formats:
        """6. block formats for the compressed copies (:class:`_FormatSearch`)."""
        return _FormatSearch(self, size, scale).run()

    def confirm_compressed(self, f: _Formats) -> fm.Fidelity | None:
        """The compressed copies of ``f`` on every active texel (None: nothing compressed)."""
        if f.state == "png" and f.base == "png":
            return None
        judge = self.judge
        compressed = judge.run(True, parts=f.parts)
        full_base = judge.sampled(f.parts["base"], True)
        compressed.base = fm.base_fidelity(
            self.ref, full_base.raw["base"], self.face, full_base.readers["base"]
        )
        return compressed

    def run(self) -> Choice:
        fx, H, judge = self.fx, self.H, self.judge
        # 1. a provisional scale at full size (or the manifest's)
        scale = fx.scale if fx.scale is not None else self.best_scale(H, "pd_scale (full size)")
        size = self.state_size(scale)
        # 3. the scale at that size: the least error, clipping included
        if fx.scale is None and size != H:
            scale = self.best_scale(size, "pd_scale")
        judge.set("states", self.states(size, scale))
        mask_size = self.mask_size()
        judge.set("masks", self.masks(mask_size))
        self.face = self.ref.face_texels(self.o.screen_texels)
        size, mask_size, scale, png, fmts, compressed = self.confirm(size, mask_size, scale)
        fmts, compressed = self.refuse_until_inside(size, scale, fmts, compressed)
        return Choice(
            wrinkle_size=size,
            mask_size=mask_size,
            pd_scale=float(scale),
            base_format=fmts.base,
            state_format=fmts.state,
            clipped_texels=clipped_texels(self.levels[size], scale),
            png=png,
            compressed=compressed,
            states=np.asarray(self.levels[size], _F),
            tried=self.tried,
            notes=self.notes,
            budget=self.budget,
            compressed_budget=self.cbudget,
        )

    def confirm(
        self, size: int, mask_size: int, scale: float
    ) -> tuple[int, int, float, fm.Fidelity, _Formats, fm.Fidelity | None]:
        """5. confirm on every active texel: the PNG copies, beside step 6 (the formats screened
        for these sizes, then their compressed copies confirmed) and the PNG base alone over the
        whole face (three independent measurements: two threads when the thread budget allows;
        the formats' screens are what they would be after the confirmation, which changes no
        part they read, and the PNG's parts are its own copy of the kept ones). While the PNG is
        over the budget, raise sizes (then screen the formats again)."""
        fx, H, m0, judge, budget, tried = (
            self.fx,
            self.H,
            self.m0,
            self.judge,
            self.budget,
            self.tried,
        )
        kept = dict(judge.parts)

        def formats_confirmed() -> tuple[_Formats, fm.Fidelity | None]:
            f = self.formats(size, scale)
            return f, self.confirm_compressed(f)

        (fmts, compressed), face_png, png = reuse.map_threads(
            _call,
            [
                formats_confirmed,
                lambda: fm.base_fidelity(
                    self.ref, self.base_texels, None, self.png_base["base_reader"]
                ),
                lambda: judge.run(True, parts=kept),
            ],
        )
        tried.append(Tried("confirmed (png)", [size, mask_size], *png.score(), png.inside(budget)))
        raised = False
        while not png.inside(budget) and (
            (fx.mask is None and mask_size < m0) or (fx.wrinkle is None and size < H)
        ):
            raised = True
            if fx.mask is None and mask_size < m0:
                mask_size *= 2
                judge.set("masks", self.masks(mask_size))
            else:
                size *= 2
                if fx.scale is None:
                    scale = self.best_scale(size, "pd_scale")
                judge.set("states", self.states(size, scale))
            png = judge.run(True)
            tried.append(Tried("raised (png)", [size, mask_size], *png.score(), png.inside(budget)))
        if not png.inside(budget):
            self.notes.append(
                f"over the budget ({budget.describe()} degrees inside the active regions) even "
                f"at {size}^2 states and {mask_size}^2 masks: worst {png.worst.pose} p99 "
                f"{png.worst.overall.p99:.2f}"
            )
        png.base = face_png  # all the face
        if raised:
            fmts = self.formats(size, scale)
            compressed = self.confirm_compressed(fmts)
        return size, mask_size, scale, png, fmts, compressed

    def refuse_until_inside(
        self, size: int, scale: float, fmts: _Formats, compressed: fm.Fidelity | None
    ) -> tuple[_Formats, fm.Fidelity | None]:
        """The compressed copies confirmed inside their budget: a format the screen passed and
        every active texel does not is not shipped (the states' first, then the base's, unless
        the manifest fixes it), and the formats are screened again without it."""
        fx, tried, cbudget = self.fx, self.tried, self.cbudget
        while True:
            tried.extend(fmts.tried)
            if compressed is None:
                break
            inside = compressed.inside(cbudget)
            tried.append(
                Tried(
                    "confirmed (compressed)", [fmts.state, fmts.base], *compressed.score(), inside
                )
            )
            if inside:
                break
            part = next(
                (
                    (name, f)
                    for name, f, fixed_f in (
                        ("state", fmts.state, fx.state_format),
                        ("base", fmts.base, fx.base_format),
                    )
                    if f != "png" and fixed_f in (None, "auto")
                ),
                None,
            )
            if part is None:
                self.notes.append(
                    f"compressed copies over their budget ({cbudget.describe()} degrees) on every "
                    f"active texel: worst {compressed.worst.pose} p99 "
                    f"{compressed.worst.overall.p99:.2f}"
                )
                break
            self.refused[part[0]].add(part[1])
            fmts = self.formats(size, scale)
            compressed = self.confirm_compressed(fmts)
        return fmts, compressed


class _FormatSearch:
    """Step 6 of :func:`search` for the states at ``size`` / ``scale`` and the kept masks: block
    formats for the compressed copies (states first, then the base), screened: only the blocks
    the reference being judged reads are encoded (blocks are independent); small maps are
    encoded whole, every map of a format in one encoder pass. The kept parts stay the PNG
    copies'."""

    def __init__(self, s: _Search, size: int, scale: float) -> None:
        self.s, self.scale = s, scale
        self.found: list[Tried] = []
        self.kept = dict(s.judge.parts)
        self.state_q = np.stack([ship.pd_texels(np.asarray(x), scale)[0] for x in s.levels[size]])
        self.trips = _RoundTrips(
            {
                **{f"state {k}": q for k, q in enumerate(self.state_q)},
                "base": s.base_texels[..., :2],
            },
            s.o.whole_map_blocks,
        )
        self.state_names = [f"state {k}" for k in range(len(self.state_q))]
        self.state_format = _factory(self._state_format)
        self.base_format = _factory(self._base_format)

    def reads(self, r: fre.Reference) -> np.ndarray:
        part = self.s.judge.sampled(self.kept["masks"], r is self.s.judge.fine)
        leaks = [lk[0] for lk in (part.leaks or []) if lk is not None]
        return np.concatenate([r.union, *leaks])

    def _state_format(self, f: str) -> Candidate:
        state_q, names, shape = self.state_q, self.state_names, self.s.ref.shape

        def make(r: fre.Reference) -> dict[str, Any]:
            need = fsa.taps(state_q.shape[1:3], shape, self.reads(r))
            got = self.trips.get(f, dict.fromkeys(names, need))
            texels = np.stack([got[n] for n in names])
            return {"states": texels, "states_reader": ship.pd_reader(self.scale, quantise=False)}

        return make

    def _base_format(self, f: str) -> Candidate:
        base_texels, shape, face = self.s.base_texels, self.s.ref.shape, self.s.face

        def make(r: fre.Reference) -> dict[str, Any]:
            need = fsa.taps(base_texels.shape[:2], shape, np.concatenate([self.reads(r), face]))
            xy = self.trips.get(f, {"base": need})["base"]
            return {"base": xy, "base_reader": ship.base_reader("rg")}

        return make

    def state_edges_ok(self, f: str) -> bool:
        """The copy must not clip where the PNG does not (the validator's rule, WP-MAP-004)."""
        state_q, names = self.state_q, self.state_names
        limit = self.s.o.max_clipped_fraction * state_q.shape[1] * state_q.shape[2]
        got = self.trips.get(f, {n: ship.near_edge_texels(q) for n, q in zip(names, state_q)})
        for n, q in zip(names, state_q):
            edges = ship.edge_texels(got[n])
            if edges > max(limit, ship.edge_texels(q)):
                at = f"{f}: {edges} texels at the end of the range"
                self.found.append(Tried("state format (clipping, WP-MAP-004)", at, 0.0, 0.0, False))
                return False
        return True

    def run(self) -> _Formats:
        s = self.s
        judge, fx, o = s.judge, s.fx, s.o
        state_fmt = pick_format(
            judge,
            fx.state_format,
            [f for f in o.formats if f not in s.refused["state"]],
            s.cbudget,
            self.found,
            "state format",
            self.state_format,
            keeps=self.state_edges_ok,
        )
        if state_fmt != "png":
            judge.set("states", self.state_format(state_fmt))
        base_fmt = pick_format(
            judge,
            fx.base_format,
            [f for f in o.formats if f not in s.refused["base"]],
            s.cbudget,
            self.found,
            "base format",
            self.base_format,
            alone=lambda make: _base_alone(s.ref, make(judge.coarse), s.face),
        )
        if base_fmt != "png":
            judge.set("base", self.base_format(base_fmt))
        parts = dict(judge.parts)
        judge.parts = self.kept
        return _Formats(state_fmt, base_fmt, parts, self.found)


@dataclass
class _Formats:
    """Step 6's choice: the block formats of states and base (``"png"``: none), the parts the
    compressed copies are judged with, and the candidates tried."""

    state: str
    base: str
    parts: dict[str, Candidate]
    tried: list[Tried]
