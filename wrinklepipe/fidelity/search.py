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

import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wrinklepipe import reuse
from wrinklepipe.fidelity import metric as fm
from wrinklepipe.fidelity import pyramid, ship
from wrinklepipe.fidelity import reference as fre
from wrinklepipe.fidelity import sampling as fsa
from wrinklepipe.metrics import Budget

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
class Tried:
    """One candidate: what was tried, its worst pose (p99, mean degrees), and the verdict."""

    step: str
    value: Any
    p99: float
    mean: float
    ok: bool
    screened_only: bool = False

    def to_json(self) -> dict[str, Any]:
        return {
            "step": self.step,
            "value": self.value,
            "worst_p99_deg": round(self.p99, 4),
            "worst_mean_deg": round(self.mean, 4),
            "ok": self.ok,
            "screened_only": self.screened_only,
        }


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


def scale_candidates(max_slope: float, factors: Sequence[float]) -> list[float]:
    """PD scales to try: ``max_slope`` times each factor, rounded up to a multiple of 1/64
    (exact in float32 and in every shader), distinct, largest first."""
    top = max(float(max_slope), 1.0 / 64.0)
    out = sorted({float(np.ceil(top * f * 64.0) / 64.0) for f in factors}, reverse=True)
    return [s for s in out if s > 0]


def clipped_texels(level: np.ndarray, scale: float) -> list[int]:
    """Per state: texels stored at the end of the range at ``scale`` (:func:`ship.edge_texels`,
    the one clipped count)."""
    return [ship.edge_texels(ship.pd_texels(x, scale)[0]) for x in level]


# ------------------------------------------------------------------------------------------------
# the search


class Judge:
    """Evaluates candidates on the coarse and the full reference, keeping what does not change.

    A candidate is a function of the reference it is judged on returning what
    :func:`~wrinklepipe.fidelity.metric.sample` takes (``base=``, ``states=`` with
    ``states_reader=``, ``masks=`` with ``support=``), so a block-format candidate encodes only the
    blocks that reference reads. Each candidate is sampled once per reference (screened, then
    kept, then confirmed: the same samples); the search's factories hand out one candidate
    object per choice (:func:`_once`)."""

    def __init__(self, ref: fre.Reference, screen_texels: int) -> None:
        self.fine = ref
        self.coarse = ref.coarse(screen_texels)
        self.parts: dict[str, Candidate] = {}
        self._sampled: dict[tuple[int, bool], tuple[Candidate, fm.Samples]] = {}
        self._lock = threading.Lock()
        self._making: dict[tuple[int, bool], threading.Lock] = {}

    @property
    def screens(self) -> bool:
        return self.coarse is not self.fine

    def sampled(self, make: Candidate, fine: bool) -> fm.Samples:
        """The samples of a candidate on the full (``fine``) or the coarse reference (made
        once: a thread asking for samples another is making waits for them)."""
        fine = fine and self.screens
        key = (id(make), fine)
        with self._lock:
            making = self._making.setdefault(key, threading.Lock())
        with making:
            hit = self._sampled.get(key)
            if hit is None:
                ref = self.fine if fine else self.coarse
                hit = (make, fm.sample(ref, **make(ref)))  # the candidate kept: its id its own
                self._sampled[key] = hit
        return hit[1]

    def set(self, name: str, make: Candidate) -> None:
        """Keep a shipped part (its samples are made when first needed)."""
        self.parts[name] = make

    def full(self, name: str) -> fm.Samples:
        """The full reference's samples of a part."""
        return self.sampled(self.parts[name], True)

    def run(
        self,
        fine: bool,
        make: Candidate | None = None,
        regions: bool = False,
        parts: dict[str, Candidate] | None = None,
    ) -> fm.Fidelity:
        """The fidelity of the kept parts (or of ``parts``), with ``make`` over them."""
        ref = self.fine if fine else self.coarse
        kept = self.parts if parts is None else parts
        samples = [self.sampled(m, fine) for m in kept.values()]
        if make is not None:
            samples.append(self.sampled(make, fine))
        return fm.evaluate(ref, fm.merge(*samples), regions=regions)

    def screen(
        self, budget: Budget, tried: list[Tried], step: str, value: Any, make: Candidate
    ) -> bool:
        f = self.run(False, make)
        tried.append(Tried(step, value, *f.score(), f.inside(budget), self.screens))
        return f.inside(budget)


Candidate = Callable[[fre.Reference], dict[str, Any]]


def _once(make: Candidate) -> Candidate:
    """``make`` computed once per reference (a block-format candidate encodes its blocks once,
    whether it is screened, measured alone or kept)."""
    memo: dict[int, tuple[fre.Reference, dict[str, Any]]] = {}

    def cached(ref: fre.Reference) -> dict[str, Any]:
        hit = memo.get(id(ref))
        if hit is None:
            hit = memo[id(ref)] = (ref, make(ref))
        return hit[1]

    return cached


def _factory(build: Callable[..., Candidate]) -> Callable[..., Candidate]:
    """One candidate object per argument tuple (the judge's samples are keyed by it)."""
    made: dict[tuple[Any, ...], Candidate] = {}

    def get(*args: Any) -> Candidate:
        if args not in made:
            made[args] = _once(build(*args))
        return made[args]

    return get


def _call(fn: Callable[[], Any]) -> Any:
    return fn()


def _smallest_passing(values: Sequence[Any], passes: Callable[[Any], bool]) -> Any | None:
    """The smallest of ascending ``values`` for which ``passes`` holds, by bisection (the error
    falls as a size grows); the largest is taken to pass (the confirmation checks it)."""
    lo, hi = 0, len(values) - 1
    if hi < 0:
        return None
    while lo < hi:
        mid = (lo + hi) // 2
        if passes(values[mid]):
            hi = mid
        else:
            lo = mid + 1
    return values[lo]


@fsa.one_blas_thread
def search(
    src: Source,
    budget: Budget,
    compressed_budget: Budget | None = None,
    fixed: Fixed | None = None,
    options: SearchOptions | None = None,
) -> Choice:
    """Choose state size, mask size, PD scale and block formats by fidelity (module doc)."""
    o = options or SearchOptions()
    fx = fixed or Fixed()
    cbudget = compressed_budget or budget
    slopes = np.asarray(src.slopes, _F)
    K, H, W = slopes.shape[:3]
    if H != W:
        raise ValueError(f"the searches need square state maps, got {W} x {H}")
    grid_base = src.source_base if src.source_base is not None else src.base
    if grid_base.shape[:2] != (H, W):
        raise ValueError("the source base must be given on the state grid (source_base)")
    smallest = min(fx.wrinkle or o.min_size, H)

    def reference() -> fre.Reference:
        return fre.prepare(
            np.asarray(grid_base, _F),
            slopes,
            src.masks,
            src.poses,
            src.region_names,
            "pd",
            src.policy,
            src.footprint,
        )

    def shippable() -> tuple[np.ndarray, dict[int, np.ndarray], ship.MaskLevels]:
        return (
            ship.base_texels(src.base),
            pyramid.levels(slopes, smallest),
            ship.mask_levels(src.masks, o.min_mask_size),
        )

    # the source's full-resolution pass beside what the candidates are made from (independent
    # work, numpy's loops release the GIL: two threads when the thread budget allows)
    ref, (base_texels, levels, mask_lv) = reuse.map_threads(_call, [reference, shippable])
    judge = Judge(ref, o.screen_texels)
    tried: list[Tried] = []
    notes: list[str] = []
    png_base = {"base": base_texels, "base_reader": ship.base_reader("rgb")}
    judge.set("base", lambda r: png_base)
    m0 = int(src.masks.shape[1])

    @_factory
    def masks(m: int) -> Candidate:
        # the source's own masks cannot leak
        return lambda r: {"masks": mask_lv[m], "support": None if m != m0 else False}

    judge.set("masks", masks(m0))
    sizes = sorted(s for s in levels if s >= smallest)

    @_factory
    def states(size: int, scale: float) -> Candidate:
        return lambda r: {"states": levels[size], "states_reader": ship.pd_reader(scale)}

    def best_scale(size: int, label: str) -> float:
        u = judge.coarse.union
        top = max(
            float(np.abs(fsa.sample_at(x, ref.shape, u)).max(initial=0.0)) for x in levels[size]
        )
        # the validator's clipping rule (WP-MAP-004) counts every texel of the map, active or
        # not: a scale that clips more than it allows is never chosen, and the candidates
        # include the smallest scale that keeps every texel of the map inside the range
        limit = o.max_clipped_fraction * size * size
        level = levels[size]
        # the largest |component| of the map: its largest and its most negative value (no
        # temporaries: at full size the map is 4M texels)
        big = max(float(level.max(initial=0.0)), -float(level.min(initial=0.0)))
        safe = scale_candidates(big, (1.0,))[0]
        candidates = sorted({*scale_candidates(top, o.scale_factors), safe}, reverse=True)
        # only texels with a component above 0.99 of the smallest scale can reach the end of
        # the range (|t| >= 1 - 0.5/127): count clipping on that tail alone, as edge_texels does
        tails = _tails(level, candidates[-1])

        def clips(s: float) -> bool:
            return max(clipped_texels(tails, s), default=0) > limit

        while clips(safe):
            safe += 1.0 / 64.0
            candidates = sorted({*candidates, safe}, reverse=True)
        best: tuple[tuple[float, float], float] | None = None
        for s in candidates:
            if s < safe and clips(s):
                tried.append(Tried(f"{label} (clips, WP-MAP-004)", s, 0.0, 0.0, False))
                continue
            f = judge.run(False, states(size, s))
            tried.append(Tried(label, s, *f.score(), f.inside(budget), judge.screens))
            if best is None or f.score() < best[0]:
                best = (f.score(), s)
        return best[1]

    # 1. a provisional scale at full size (or the manifest's)
    scale = fx.scale if fx.scale is not None else best_scale(H, "pd_scale (full size)")
    # 2. the state size: the smallest that meets the budget (screened)
    if fx.wrinkle is not None:
        size = fx.wrinkle if fx.wrinkle in levels else H
        if size != fx.wrinkle:
            notes.append(f"wrinkle size {fx.wrinkle} is not a halving of {H}: kept {H}")
    else:
        size = (
            _smallest_passing(
                sizes, lambda s: judge.screen(budget, tried, "wrinkle", s, states(s, scale))
            )
            or H
        )
    # 3. the scale at that size: the least error, clipping included
    if fx.scale is None and size != H:
        scale = best_scale(size, "pd_scale")
    judge.set("states", states(size, scale))
    # 4. the mask size: the smallest that meets the budget (screened)
    mask_size = fx.mask if fx.mask in mask_lv else m0
    if fx.mask is None:
        smaller = sorted(m for m in mask_lv if m < m0)
        mask_size = (
            _smallest_passing(smaller, lambda m: judge.screen(budget, tried, "mask", m, masks(m)))
            or m0
        )
    judge.set("masks", masks(mask_size))
    face = ref.face_texels(o.screen_texels)
    # formats a screen passed but the confirmation on every active texel did not: not shipped
    refused: dict[str, set[str]] = {"state": set(), "base": set()}

    def formats(size: int, scale: float) -> _Formats:
        """6. block formats for the compressed copies (states first, then the base), screened
        with the states at ``size`` / ``scale`` and the kept masks: only the blocks the
        reference being judged reads are encoded (blocks are independent); small maps are
        encoded whole, every map of a format in one encoder pass. The kept parts stay the PNG
        copies'."""
        found: list[Tried] = []
        kept = dict(judge.parts)
        state_q = np.stack([ship.pd_texels(x, scale)[0] for x in levels[size]])
        trips = _RoundTrips(
            {**{f"state {k}": q for k, q in enumerate(state_q)}, "base": base_texels[..., :2]},
            o.whole_map_blocks,
        )
        state_names = [f"state {k}" for k in range(len(state_q))]

        def reads(r: fre.Reference) -> np.ndarray:
            part = judge.sampled(kept["masks"], r is judge.fine)
            leaks = [lk[0] for lk in (part.leaks or []) if lk is not None]
            return np.concatenate([r.union, *leaks])

        @_factory
        def state_format(f: str) -> Candidate:
            def make(r: fre.Reference) -> dict[str, Any]:
                need = fsa.taps(state_q.shape[1:3], ref.shape, reads(r))
                got = trips.get(f, dict.fromkeys(state_names, need))
                texels = np.stack([got[n] for n in state_names])
                return {"states": texels, "states_reader": ship.pd_reader(scale, quantise=False)}

            return make

        @_factory
        def base_format(f: str) -> Candidate:
            def make(r: fre.Reference) -> dict[str, Any]:
                need = fsa.taps(base_texels.shape[:2], ref.shape, np.concatenate([reads(r), face]))
                xy = trips.get(f, {"base": need})["base"]
                return {"base": xy, "base_reader": ship.base_reader("rg")}

            return make

        def state_edges_ok(f: str) -> bool:
            # the copy must not clip where the PNG does not (the validator's rule, WP-MAP-004)
            limit = o.max_clipped_fraction * state_q.shape[1] * state_q.shape[2]
            got = trips.get(f, {n: ship.near_edge_texels(q) for n, q in zip(state_names, state_q)})
            for n, q in zip(state_names, state_q):
                edges = ship.edge_texels(got[n])
                if edges > max(limit, ship.edge_texels(q)):
                    at = f"{f}: {edges} texels at the end of the range"
                    found.append(Tried("state format (clipping, WP-MAP-004)", at, 0.0, 0.0, False))
                    return False
            return True

        state_fmt = pick_format(
            judge,
            fx.state_format,
            [f for f in o.formats if f not in refused["state"]],
            cbudget,
            found,
            "state format",
            state_format,
            keeps=state_edges_ok,
        )
        if state_fmt != "png":
            judge.set("states", state_format(state_fmt))
        base_fmt = pick_format(
            judge,
            fx.base_format,
            [f for f in o.formats if f not in refused["base"]],
            cbudget,
            found,
            "base format",
            base_format,
            alone=lambda make: _base_alone(ref, make(judge.coarse), face),
        )
        if base_fmt != "png":
            judge.set("base", base_format(base_fmt))
        parts = dict(judge.parts)
        judge.parts = kept
        return _Formats(state_fmt, base_fmt, parts, found)

    def confirm_compressed(f: _Formats) -> fm.Fidelity | None:
        """The compressed copies of ``f`` on every active texel (None: nothing compressed)."""
        if f.state == "png" and f.base == "png":
            return None
        compressed = judge.run(True, parts=f.parts)
        full_base = judge.sampled(f.parts["base"], True)
        compressed.base = fm.base_fidelity(
            ref, full_base.raw["base"], face, full_base.readers["base"]
        )
        return compressed

    # 5. confirm on every active texel: the PNG copies, beside step 6 (the formats screened
    # for these sizes, then their compressed copies confirmed) and the PNG base alone over the
    # whole face (three independent measurements: two threads when the thread budget allows;
    # the formats' screens are what they would be after the confirmation, which changes no
    # part they read, and the PNG's parts are its own copy of the kept ones).
    # While the PNG is over the budget, raise sizes (then screen the formats again)
    kept = dict(judge.parts)

    def formats_confirmed() -> tuple[_Formats, fm.Fidelity | None]:
        f = formats(size, scale)
        return f, confirm_compressed(f)

    (fmts, compressed), face_png, png = reuse.map_threads(
        _call,
        [
            formats_confirmed,
            lambda: fm.base_fidelity(ref, base_texels, None, png_base["base_reader"]),
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
            judge.set("masks", masks(mask_size))
        else:
            size *= 2
            if fx.scale is None:
                scale = best_scale(size, "pd_scale")
            judge.set("states", states(size, scale))
        png = judge.run(True)
        tried.append(Tried("raised (png)", [size, mask_size], *png.score(), png.inside(budget)))
    if not png.inside(budget):
        notes.append(
            f"over the budget ({budget.describe()} degrees inside the active regions) even at "
            f"{size}^2 states and {mask_size}^2 masks: worst {png.worst.pose} p99 "
            f"{png.worst.overall.p99:.2f}"
        )
    png.base = face_png  # all the face
    if raised:
        fmts = formats(size, scale)
        compressed = confirm_compressed(fmts)
    while True:
        tried.extend(fmts.tried)
        if compressed is None:
            break
        inside = compressed.inside(cbudget)
        tried.append(
            Tried("confirmed (compressed)", [fmts.state, fmts.base], *compressed.score(), inside)
        )
        if inside:
            break
        # the screen passed, every active texel does not: that format is not shipped (the
        # states' first, then the base's), unless the manifest fixes it
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
            notes.append(
                f"compressed copies over their budget ({cbudget.describe()} degrees) on every "
                f"active texel: worst {compressed.worst.pose} p99 "
                f"{compressed.worst.overall.p99:.2f}"
            )
            break
        refused[part[0]].add(part[1])
        fmts = formats(size, scale)
        compressed = confirm_compressed(fmts)
    state_fmt, base_fmt = fmts.state, fmts.base
    return Choice(
        wrinkle_size=size,
        mask_size=mask_size,
        pd_scale=float(scale),
        base_format=base_fmt,
        state_format=state_fmt,
        clipped_texels=clipped_texels(levels[size], scale),
        png=png,
        compressed=compressed,
        states=levels[size],
        tried=tried,
        notes=notes,
        budget=budget,
        compressed_budget=cbudget,
    )


def _tails(level: np.ndarray, smallest: float) -> list[np.ndarray]:
    """Per state of ``level`` ``[K, s, s, 2]``: its texels ``[n, 1, 2]`` (in map order) whose
    larger |component| is at least 0.99 of scale ``smallest`` (the only ones that can clip at
    a scale of at least that). In chunks of rows (:func:`~wrinklepipe.fidelity.sampling.chunks`:
    the same texels, small temporaries) and two planes per chunk (a reduction over a last axis
    of 2 is ten times slower than one elementwise maximum; the same values)."""
    out = []
    for x in level:
        parts = []
        for sl in fsa.chunks(x.shape[0], max(1, fsa.CHUNK_TEXELS // max(x.shape[1], 1))):
            c = x[sl]
            amax = np.maximum(np.abs(c[..., 0]), np.abs(c[..., 1]))
            parts.append(c[amax >= 0.99 * smallest])
        out.append(np.concatenate(parts)[:, None, :])
    return out


@dataclass
class _Formats:
    """Step 6's choice: the block formats of states and base (``"png"``: none), the parts the
    compressed copies are judged with, and the candidates tried."""

    state: str
    base: str
    parts: dict[str, Candidate]
    tried: list[Tried]


class _RoundTrips:
    """Block-format round trips of the maps the format searches try
    (:func:`~wrinklepipe.fidelity.ship.block_roundtrip_many`), each block encoded once.

    Maps that hold at most ``whole_blocks`` 4x4 blocks together are encoded whole, all of
    them in one encoder pass per format, the first time a format is asked for (an encoder call
    costs tens of ms however small the map). Larger ones encode the blocks a request reads that
    no earlier request of that format did (the screen's blocks are most of what the
    confirmation reads), every map of the request in one pass; blocks are independent, so the
    texels are those of a whole-map round trip."""

    def __init__(self, maps: dict[str, np.ndarray], whole_blocks: int) -> None:
        self.maps = maps
        blocks = sum(((m.shape[0] + 3) // 4) * ((m.shape[1] + 3) // 4) for m in maps.values())
        self.eager = blocks <= whole_blocks
        self.whole: dict[str, dict[str, np.ndarray]] = {}
        self.done: dict[tuple[str, str], np.ndarray] = {}  # (format, map): blocks encoded

    def get(self, fmt: str, need: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """``{map name: its texels through fmt}`` (at least those of ``need`` are exact)."""
        if self.eager:
            if fmt not in self.whole:
                names = list(self.maps)
                maps = [self.maps[n] for n in names]
                trips = ship.block_roundtrip_many(maps, fmt, [None] * len(names))
                self.whole[fmt] = dict(zip(names, trips))
            return {n: self.whole[fmt][n] for n in need}
        have = self.whole.setdefault(fmt, {})
        todo: dict[str, np.ndarray] = {}
        for n, t in need.items():
            h, w = self.maps[n].shape[:2]
            bw = (w + 3) // 4
            done = self.done.setdefault((fmt, n), np.zeros(((h + 3) // 4) * bw, bool))
            ti = np.asarray(t, np.int64)
            block = (ti // w) // 4 * bw + (ti % w) // 4
            new = ti[~done[block]]
            if new.size:
                todo[n] = new
                done[block] = True
        if todo:
            names = list(todo)
            sources = [have.get(n, self.maps[n]) for n in names]  # encoded blocks kept
            trips = ship.block_roundtrip_many(sources, fmt, [todo[n] for n in names])
            for n, got in zip(names, trips):
                have[n] = got
        return {n: have.get(n, self.maps[n]) for n in need}


def _base_alone(ref: fre.Reference, arrays: dict[str, Any], face: np.ndarray) -> Any:
    return fm.base_fidelity(ref, arrays["base"], face, arrays.get("base_reader"))


def pick_format(
    judge: Judge,
    fixed: str | None,
    formats: Sequence[str],
    budget: Budget,
    tried: list[Tried],
    step: str,
    candidate: Callable[[str], Candidate],
    alone: Callable[[Candidate], Any] | None = None,
    keeps: Callable[[str], bool] | None = None,
) -> str:
    """The first format (smallest blocks first) whose screened candidate meets ``budget``
    (and, with ``alone``, whose own error over the face does too; with ``keeps``, for which it
    holds); ``fixed`` is measured, not chosen."""
    chosen = fixed not in (None, "auto")
    for f in [fixed] if chosen else formats:
        if f == "png":
            return "png"
        make = candidate(f)
        ok = judge.screen(budget, tried, step, f, make)
        if ok and alone is not None:
            a = alone(make)
            ok = budget.inside(a)
            if not ok:
                tried.append(Tried(step + " (base alone)", f, a.p99, a.mean, False))
        if ok and not chosen and keeps is not None:
            ok = keeps(f)
        if ok or chosen:
            return f
    return "png"
