"""How the searches of :mod:`wrinklepipe.fidelity.search` judge a candidate: the :class:`Judge`
(screened on the coarse reference, confirmed on every active texel, what does not change kept),
one candidate object per choice, the block-format round trips each block encoded once, the
first format that meets a budget (:func:`pick_format`), and the record of what was tried."""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from wrinklepipe.fidelity import metric as fm
from wrinklepipe.fidelity import reference as fre
from wrinklepipe.fidelity import ship
from wrinklepipe.metrics import Budget


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
