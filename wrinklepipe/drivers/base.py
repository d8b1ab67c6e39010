"""What every driver shares: the context it reads, the result it returns, and the registry.

A driver turns an animation (keys, blend-shape weights, bone positions, a deforming mesh) into
**linear** weights ``[frames, regions, states]`` float32: what the shader receives, before the
per-texel policy of :func:`wrinklepipe.model.activations`. Under the ``signed`` policy the states
axis has length 1 (Oat's single weight in [-1, 1]). Per-vertex drivers (``bones``, ``dynamic``)
return ``[frames, vertices, states]`` with ``per_vertex = True``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from contextvars import ContextVar
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from wrinklepipe.asset import Mesh, WrinkleAsset
from wrinklepipe.errors import InputError, Problem
from wrinklepipe.model import POLICIES
from wrinklepipe.presets import jimenez

#: Default sampling rate when neither the call nor the driver spec gives one.
DEFAULT_FPS = 30.0


class Rig(Protocol):
    """A skeleton with its animation, as the ``bones`` driver reads it (the pipeline gives one
    through :attr:`DriverContext.read_rig`; :class:`wrinklepipe.readers.rig.GltfRig` reads glTF)."""

    joint_names: tuple[str, ...]
    joints: np.ndarray | None
    skin_weights: np.ndarray | None

    def key_times(self) -> np.ndarray: ...

    def joint_matrices(self, times: Sequence[float | None]) -> np.ndarray: ...


@dataclass(frozen=True)
class MorphTrack:
    """One animation channel of morph-target weights, as read from a glTF (the pipeline gives
    a reader through :attr:`DriverContext.read_morph_tracks`; :func:`wrinklepipe.gltf.animation.
    read_morph_tracks` reads glTF): the target ``names``, key ``times`` [N] (strictly
    increasing) and ``values`` [N, M] (CUBICSPLINE: [N, 3, M], in-tangent, value,
    out-tangent), ``interpolation`` LINEAR | STEP | CUBICSPLINE."""

    names: tuple[str, ...]
    times: np.ndarray
    values: np.ndarray
    interpolation: str = "LINEAR"
    #: the glTF node whose morph weights the channel drives (None: not from a glTF node)
    node: int | None = None


@dataclass(frozen=True)
class MorphClip:
    """One animation of a glTF that drives morph-target weights: its name (or ``animation
    <i>``), its index among the file's animations, and its weight tracks (the pipeline gives a
    reader of every clip through :attr:`DriverContext.read_morph_clips`)."""

    name: str
    index: int
    tracks: tuple[MorphTrack, ...]

    def moving(self, inputs: Sequence[str] = ()) -> tuple[str, ...]:
        """The targets (of ``inputs``, or all) whose weight is not 0 at some key."""
        want = set(inputs)
        out: list[str] = []
        for t in self.tracks:
            v = np.abs(np.asarray(t.values, np.float64)).reshape(-1, len(t.names))
            peak = v.max(axis=0) if v.size else np.zeros(len(t.names))
            out += [n for n, p in zip(t.names, peak) if p > 0 and (not want or n in want)]
        return tuple(dict.fromkeys(out))


@dataclass
class DriverContext:
    """Everything a driver may read besides its own spec.

    ``region_states`` ``[R, K]`` is 1 where region r drives state k (see
    :meth:`WrinkleAsset.region_state_matrix`). ``expressions`` is ``{expression: {region: w}}``.
    ``root`` resolves relative file names in a spec. ``source`` names the spec in messages.
    ``read_rig`` opens a skinned file a ``bones`` spec names and ``read_morph_tracks`` reads
    the morph-weight animation of a glTF a ``curves``, ``blendshapes`` or ``dynamic`` spec
    names (the layer that builds the context supplies both: drivers read no glTF themselves).
    """

    regions: tuple[str, ...]
    states: tuple[str, ...]
    region_states: np.ndarray | None = None
    policy: str = "clamp01"
    expressions: dict[str, dict[str, float]] = field(default_factory=dict)
    mesh: Mesh | None = None
    root: Path = Path(".")
    fps: float = DEFAULT_FPS
    source: str = "<driver>"
    read_rig: Callable[[Path], Rig] | None = None
    read_morph_tracks: Callable[[Path], list[MorphTrack]] | None = None
    read_morph_clips: Callable[[Path], list[MorphClip]] | None = None

    def __post_init__(self) -> None:
        self.regions = tuple(str(r) for r in self.regions)
        self.states = tuple(str(s) for s in self.states)
        if self.policy not in POLICIES:
            raise InputError(f"unknown policy {self.policy!r}", self.source)
        if self.region_states is None:
            self.region_states = np.ones((len(self.regions), len(self.states)), np.float32)
        self.region_states = np.asarray(self.region_states, np.float32)
        self.root = Path(self.root)

    @property
    def weight_states(self) -> int:
        """Length of the states axis of the weights (1 under ``signed``)."""
        return 1 if self.policy == "signed" else len(self.states)

    def spread(self, per_region: np.ndarray) -> np.ndarray:
        """``[F, R]`` region weights -> ``[F, R, K]`` over the states each region drives."""
        w = np.asarray(per_region, np.float32)
        if self.policy == "signed":
            return w[..., None].astype(np.float32)
        return (w[..., None] * self.region_states[None]).astype(np.float32)

    @classmethod
    def from_asset(
        cls,
        asset: WrinkleAsset,
        root: str | Path = ".",
        fps: float = DEFAULT_FPS,
        read_rig: Callable[[Path], Rig] | None = None,
        read_morph_tracks: Callable[[Path], list[MorphTrack]] | None = None,
        source: str = "<driver>",
        read_morph_clips: Callable[[Path], list[MorphClip]] | None = None,
    ) -> DriverContext:
        """``source``: the file the drivers come from (the manifest), named in messages."""
        return cls(
            source=source,
            regions=asset.region_names,
            states=asset.state_names,
            region_states=asset.region_state_matrix(),
            policy=asset.policy,
            expressions=dict(asset.expressions),
            mesh=asset.mesh,
            root=Path(root),
            fps=fps,
            read_rig=read_rig,
            read_morph_tracks=read_morph_tracks,
            read_morph_clips=read_morph_clips,
        )

    @classmethod
    def from_manifest(
        cls,
        manifest: Any,
        mesh: Mesh | None = None,
        read_rig: Callable[[Path], Rig] | None = None,
        read_morph_tracks: Callable[[Path], list[MorphTrack]] | None = None,
        read_morph_clips: Callable[[Path], list[MorphClip]] | None = None,
    ) -> DriverContext:
        """From a :class:`wrinklepipe.sources.manifest.Manifest` (the mesh is loaded by the
        caller)."""
        states = tuple(s.name for s in manifest.states)
        rs = np.zeros((len(manifest.regions), len(states)), np.float32)
        for i, r in enumerate(manifest.regions):
            for k, s in enumerate(states):
                rs[i, k] = 1.0 if (not r.states or s in r.states) else 0.0
        expressions = manifest.expressions
        if isinstance(expressions, str):
            expressions = jimenez.expression_table() if expressions == "jimenez" else {}
        return cls(
            regions=tuple(r.name for r in manifest.regions),
            states=states,
            region_states=rs,
            policy=manifest.policy,
            expressions=dict(expressions),
            mesh=mesh,
            root=manifest.root,
            source=str(manifest.path),
            read_rig=read_rig,
            read_morph_tracks=read_morph_tracks,
            read_morph_clips=read_morph_clips,
        )


@dataclass
class DriverResult:
    """Weights over time. ``weights`` ``[F, R, K]`` float32 (linear, before the policy)."""

    kind: str
    times: np.ndarray  # [F] seconds
    weights: np.ndarray  # [F, R, K]
    regions: tuple[str, ...]  # labels of axis 1 (vertex indices "0".."V-1" when per_vertex)
    states: tuple[str, ...]  # labels of axis 2
    per_vertex: bool = False
    notes: list[str] = field(default_factory=list)
    #: what the driver read (JSON): its inputs, those that move, and for a glTF file the clip
    #: chosen (:class:`wrinklepipe.drivers.clips.ClipChoice`); the report and the validator's
    #: rig rules say it
    source: dict[str, Any] = field(default_factory=dict)

    def to_json(self, digits: int = 6) -> dict[str, Any]:
        """Deterministic JSON: ``weights[frame][region][state]`` rounded to ``digits``."""
        w = np.round(self.weights.astype(np.float64), digits) + 0.0  # no -0.0
        return {
            "kind": self.kind,
            "times": [round(float(t), 9) for t in self.times],
            "regions": list(self.regions),
            "states": list(self.states),
            "per_vertex": self.per_vertex,
            "weights": w.tolist(),
            "notes": list(self.notes),
        }


DriverFn = Callable[[DriverContext, Mapping[str, Any], "np.ndarray | None"], DriverResult]

#: kind -> driver function ``fn(ctx, spec, times) -> DriverResult``.
DRIVERS: dict[str, DriverFn] = {}


def register(kind: str) -> Callable[[DriverFn], DriverFn]:
    """Register a driver under ``kind`` (later registrations replace earlier ones)."""

    def deco(fn: DriverFn) -> DriverFn:
        DRIVERS[kind] = fn
        return fn

    return deco


def evaluate(
    kind: str,
    ctx: DriverContext,
    spec: Mapping[str, Any] | None = None,
    times: Sequence[float] | np.ndarray | None = None,
) -> DriverResult:
    """Run the driver ``kind`` on ``spec`` (a manifest ``[[drivers]]`` table) at ``times``."""
    if kind not in DRIVERS:
        raise InputError(
            f"unknown driver {kind!r}; expected one of {', '.join(sorted(DRIVERS))}", ctx.source
        )
    t = None if times is None else np.asarray(times, np.float64).reshape(-1)
    per_frame = max(1, len(ctx.regions) * ctx.weight_states)
    limit = max(1, min(MAX_FRAMES, MAX_WEIGHT_VALUES // per_frame))
    if t is not None and t.size > limit:
        raise InputError(
            [Problem(ctx.source, f"{kind} driver: {t.size} frames, over the cap of {limit}")]
        )
    token = _FRAME_LIMIT.set(limit)
    try:
        res = DRIVERS[kind](ctx, dict(spec or {}), t)
    except TooManyFrames as exc:
        raise InputError([Problem(ctx.source, f"{kind} driver: {exc}")]) from None
    finally:
        _FRAME_LIMIT.reset(token)
    if res.weights.ndim != 3 or res.weights.shape[0] != res.times.shape[0]:
        raise RuntimeError(f"driver {kind!r} returned weights of shape {res.weights.shape}")
    return res


#: The most frames a driver samples (12 hours at 24 fps), and the most weights ``frames x
#: regions x states`` it returns (256 MB of float32): checked before the samples are made.
MAX_FRAMES = 1 << 20
MAX_WEIGHT_VALUES = 1 << 26
_FRAME_LIMIT: ContextVar[int] = ContextVar("wrinklepipe_frame_limit", default=MAX_FRAMES)


class TooManyFrames(ValueError):
    """Keys and fps that make more frames than :func:`frame_times` may sample."""

    def __init__(self, t0: float, t1: float, fps: float, frames: float, limit: int) -> None:
        self.t0, self.t1, self.fps, self.frames, self.limit = t0, t1, fps, frames, limit
        super().__init__(
            f"keys from {t0:g} to {t1:g} s at {fps:g} fps make {frames:.4g} frames, over the "
            f"cap of {limit} for this asset (at most {MAX_FRAMES} frames, {MAX_WEIGHT_VALUES} "
            "weights over regions and states): shorten the keys' time span or lower fps"
        )


def frame_times(t0: float, t1: float, fps: float) -> np.ndarray:
    """Sample times ``t0, t0 + 1/fps, ...`` up to and including ``t1`` (and ``t1`` itself).
    Refuses (:class:`TooManyFrames`) more frames than the evaluation allows, before any is
    made."""
    if t1 < t0:
        t0, t1 = t1, t0
    span = (t1 - t0) * fps
    limit = _FRAME_LIMIT.get()
    if not np.isfinite(span) or span + 1 > limit:
        raise TooManyFrames(t0, t1, fps, span + 1, limit)
    n = int(np.floor(span + 1e-9)) + 1
    t = t0 + np.arange(n, dtype=np.float64) / fps
    if t[-1] < t1 - 1e-9:
        t = np.append(t, t1)
    return t


def policy_weights(weights: np.ndarray, policy: str) -> np.ndarray:
    """The activation a texel gets whose mask is 1 in one region and 0 in the others.

    ``weights`` ``[..., R, K]``. ``clamp01``/``renormalize``: ``clip(w, 0, 1)``; ``additive``:
    ``w``; ``signed``: ``clip(w, -1, 1)`` (``K = 1``); ``lerp``: clip then convex over K. Where
    masks overlap the per-texel policy (:func:`wrinklepipe.model.activations`) is what counts.
    """
    w = np.asarray(weights, np.float32)
    if policy in ("clamp01", "renormalize"):
        return np.clip(w, 0.0, 1.0)
    if policy == "additive":
        return w.copy()
    if policy == "signed":
        return np.clip(w, -1.0, 1.0)
    if policy == "lerp":
        a = np.clip(w, 0.0, 1.0)
        return (a / np.maximum(a.sum(axis=-1, keepdims=True), 1.0)).astype(np.float32)
    raise ValueError(f"unknown policy {policy!r}")


def spec_problem(ctx: DriverContext, message: str, key: str = "") -> InputError:
    """An :class:`InputError` naming the driver spec's source and key."""
    return InputError([Problem(ctx.source, message, key)])


def resolve(ctx: DriverContext, name: str) -> Path:
    p = Path(name)
    return p if p.is_absolute() else ctx.root / p
