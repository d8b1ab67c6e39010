"""``curves``: weights keyed over time by an artist (Oat's animated wrinkles).

Spec (a manifest ``[[drivers]]`` table)::

    kind = "curves"
    interpolation = "linear"          # linear | cubic | step
    fps = 30                          # sampling rate of the keys' time range
    file = "anim.csv"                 # optional: CSV, JSON or glTF/GLB (morph-weight animation)
    [drivers.keys]                    # optional: {name: [[time, value], ...]}
    forehead_outer_l = [[0, 0], [1, 1]]
    "glabella:compress" = [[0, 0], [1, 0.5]]   # region:state drives one state only

A name is a region (all the states it drives) or ``region:state``. Before the first key and after
the last the value holds. ``cubic`` is the not-a-knot cubic spline through the keys (exact on any
cubic polynomial with 4 or more keys; fewer keys give the polynomial of lower degree).

CSV: a header ``time,<name>,<name>...`` then one row per key time; an empty cell is no key.
JSON: ``{"interpolation": ..., "keys": {name: [[t, v], ...]}}`` or just ``{name: [[t, v], ...]}``.
glTF: every animation channel whose path is ``weights`` gives one curve per morph target, named by
``mesh.extras.targetNames``; targets whose names are not regions are ignored (and noted).
"""

from __future__ import annotations

import csv
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from wrinklepipe.drivers.base import (
    DriverContext,
    DriverResult,
    MorphTrack,
    frame_times,
    register,
    resolve,
    spec_problem,
)
from wrinklepipe.drivers.clips import ClipChoice, choose_clip
from wrinklepipe.errors import InputError, Problem, input_error
from wrinklepipe.geometry.keyframes import sample_channel_at
from wrinklepipe.io.json_safe import loads_json
from wrinklepipe.names import unknown_names
from wrinklepipe.suffixes import GLTF_SUFFIXES, is_gltf

INTERPOLATIONS = ("linear", "cubic", "step")

Keys = dict[str, np.ndarray]  # name -> [n, 2] (time, value), times strictly increasing


def sample(
    key_times: np.ndarray, key_values: np.ndarray, times: np.ndarray, interpolation: str = "linear"
) -> np.ndarray:
    """One curve at ``times`` ``[F]``; holds outside the keys."""
    kt = np.asarray(key_times, np.float64)
    kv = np.asarray(key_values, np.float64)
    t = np.asarray(times, np.float64)
    if kt.size == 1:
        return np.full(t.shape, kv[0])
    if interpolation == "step":
        i = np.clip(np.searchsorted(kt, t, side="right") - 1, 0, kt.size - 1)
        return kv[i]
    if interpolation == "cubic" and kt.size >= 3:
        # deferred: scipy.interpolate (and the scipy.optimize it brings) is ~0.4 s of import
        # time (0.1-0.2 s of a command's start-up, measured), and only cubic keys need it
        from scipy.interpolate import CubicSpline

        tc = np.clip(t, kt[0], kt[-1])
        return CubicSpline(kt, kv, bc_type="not-a-knot")(tc)
    return np.interp(t, kt, kv)


def check_keys(raw: Mapping[str, Any], where: str, key: str = "keys") -> Keys:
    """``{name: [[t, v], ...]}`` -> sorted ``{name: [n, 2]}``; refuses bad or repeated times."""
    out: Keys = {}
    problems = []
    for name, pairs in raw.items():
        try:
            a = np.asarray(pairs, dtype=np.float64)
        except (TypeError, ValueError):
            a = np.zeros((0, 0))
        if a.ndim != 2 or a.shape[1] != 2 or a.shape[0] == 0 or not np.isfinite(a).all():
            problems.append(
                Problem(where, "expected [[time, value], ...] with finite numbers", f"{key}.{name}")
            )
            continue
        a = a[np.argsort(a[:, 0], kind="stable")]
        if np.any(np.diff(a[:, 0]) <= 0):
            problems.append(Problem(where, "two keys at the same time", f"{key}.{name}"))
            continue
        out[str(name)] = a
    if problems:
        raise InputError(problems)
    return out


def read_curves_csv(path: str | Path) -> Keys:
    """CSV with a ``time`` column and one column per curve (empty cell = no key)."""
    path = Path(path)
    try:
        rows = list(csv.reader(path.read_text(encoding="utf-8").splitlines()))
    except (OSError, UnicodeDecodeError) as exc:
        raise input_error(path, f"cannot read CSV: {exc}") from None
    rows = [r for r in rows if r and not r[0].lstrip().startswith("#")]
    if not rows or rows[0][0].strip().lower() != "time":
        raise input_error(path, "first column of the header must be 'time'", "line 1")
    header = [h.strip() for h in rows[0]]
    raw: dict[str, list[list[float]]] = {h: [] for h in header[1:]}
    for ln, r in enumerate(rows[1:], start=2):
        try:
            t = float(r[0])
            for h, cell in zip(header[1:], r[1:]):
                if cell.strip():
                    raw[h].append([t, float(cell)])
        except ValueError:
            raise input_error(path, f"not a number in {r!r}", f"line {ln}") from None
    return check_keys({k: v for k, v in raw.items() if v}, str(path))


def read_curves_json(path: str | Path) -> tuple[Keys, str | None]:
    """JSON ``{"keys": {...}, "interpolation": ...}`` or ``{name: [[t, v], ...]}``."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise input_error(path, f"cannot read JSON: {exc.strerror or exc}") from None
    doc = loads_json(data, path)
    if not isinstance(doc, dict):
        raise input_error(path, "expected a JSON object")
    keys = doc.get("keys", doc)
    if not isinstance(keys, dict):
        raise input_error(path, "'keys' must be an object", "keys")
    interp = doc.get("interpolation") if "keys" in doc else None
    return check_keys(keys, str(path)), interp


def morph_animation(
    ctx: DriverContext,
    path: str | Path,
    times: np.ndarray | None = None,
    fps: float = 30.0,
    clip: str | int | None = None,
    inputs: Sequence[str] = (),
) -> tuple[np.ndarray, tuple[str, ...], np.ndarray]:
    """The morph-target weights a glTF's animation drives, sampled by
    :func:`sample_morph_tracks`: :func:`morph_clip_animation` without the record."""
    return morph_clip_animation(ctx, path, times, fps, clip, inputs)[:3]  # type: ignore[return-value]


def morph_clip_animation(
    ctx: DriverContext,
    path: str | Path,
    times: np.ndarray | None = None,
    fps: float = 30.0,
    clip: str | int | None = None,
    inputs: Sequence[str] = (),
) -> tuple[np.ndarray, tuple[str, ...], np.ndarray, ClipChoice | None]:
    """The morph-target weights of the clip a driver reads from a glTF (``clip``: its name or
    index, as the spec's ``clip`` key gives it; else :func:`wrinklepipe.drivers.clips.
    choose_clip` chooses, preferring a clip that moves ``inputs``) and the record of the choice.
    Read through ``ctx.read_morph_clips`` (every clip), or ``ctx.read_morph_tracks`` (the first
    animation only: no choice, no record)."""
    if ctx.read_morph_clips is not None:
        try:
            chosen, choice = choose_clip(
                ctx.read_morph_clips(Path(path)), clip, inputs, Path(path).name
            )
        except ValueError as exc:
            raise spec_problem(ctx, str(exc), "clip") from None
        return (*sample_morph_tracks(chosen.tracks, times, fps), choice)
    if ctx.read_morph_tracks is None:
        raise spec_problem(
            ctx, "no glTF animation reader was given (DriverContext.read_morph_clips)", "file"
        )
    if clip is not None:
        raise spec_problem(ctx, "'clip' needs a reader of every clip (read_morph_clips)", "clip")
    return (*sample_morph_tracks(ctx.read_morph_tracks(Path(path)), times, fps), None)


def sample_morph_tracks(
    tracks: Sequence[MorphTrack], times: np.ndarray | None = None, fps: float = 30.0
) -> tuple[np.ndarray, tuple[str, ...], np.ndarray]:
    """Sample morph-weight tracks: ``(times [F], target names, weights [F, M])``; with
    ``times`` None at ``fps`` over the tracks' own time range. LINEAR, STEP and CUBICSPLINE
    (glTF's Hermite); a name two tracks share takes the first track's curve."""
    if times is None:
        t0 = min(float(k.times[0]) for k in tracks)
        t1 = max(float(k.times[-1]) for k in tracks)
        times = frame_times(t0, t1, fps)
    all_names: list[str] = []
    cols: list[np.ndarray] = []
    for k in tracks:
        w = sample_channel_at(
            np.asarray(k.times, np.float64),
            np.asarray(k.values, np.float64),
            times,
            k.interpolation,
            "weights",
        )
        for j, n in enumerate(k.names):
            if n not in all_names:
                all_names.append(n)
                cols.append(w[:, j])
    return np.asarray(times, np.float64), tuple(all_names), np.stack(cols, axis=1)


def load_keys(ctx: DriverContext, spec: Mapping[str, Any]) -> tuple[Keys, str, list[str]]:
    """Keys from ``spec['file']`` (CSV / JSON) merged with ``spec['keys']``; and interpolation."""
    interp = spec.get("interpolation")
    keys: Keys = {}
    notes: list[str] = []
    if "file" in spec:
        path = resolve(ctx, str(spec["file"]))
        if not path.is_file():
            raise spec_problem(ctx, f"file not found: {path}", "file")
        suffix = path.suffix.lower()
        if suffix == ".csv":
            keys.update(read_curves_csv(path))
        elif suffix == ".json":
            k, i = read_curves_json(path)
            keys.update(k)
            interp = interp or i
        elif suffix not in GLTF_SUFFIXES:
            raise spec_problem(
                ctx, f"unsupported curves file {path.name} (csv, json, gltf)", "file"
            )
    if "keys" in spec:
        if not isinstance(spec["keys"], Mapping):
            raise spec_problem(ctx, "'keys' must be a table {name: [[t, v], ...]}", "keys")
        keys.update(check_keys(spec["keys"], ctx.source))
    interp = interp or "linear"
    if interp not in INTERPOLATIONS:
        raise spec_problem(ctx, f"unknown interpolation {interp!r}", "interpolation")
    return keys, interp, notes


def keys_range(keys: Keys) -> tuple[float, float]:
    return (min(float(a[0, 0]) for a in keys.values()), max(float(a[-1, 0]) for a in keys.values()))


def sample_keys(keys: Keys, names: Sequence[str], times: np.ndarray, interp: str) -> np.ndarray:
    """``[F, len(names)]``: each named curve at ``times`` (0 for a name without keys)."""
    out = np.zeros((len(times), len(names)), np.float64)
    for j, n in enumerate(names):
        if n in keys:
            out[:, j] = sample(keys[n][:, 0], keys[n][:, 1], times, interp)
    return out


def _target_index(ctx: DriverContext, name: str, key: str) -> tuple[int, int | None]:
    region, _, state = name.partition(":")
    if region not in ctx.regions:
        raise spec_problem(ctx, unknown_names("region", [region], ctx.regions), key)
    if state and state not in ctx.states:
        raise spec_problem(ctx, unknown_names("state", [state], ctx.states), key)
    return ctx.regions.index(region), (ctx.states.index(state) if state else None)


def curves_to_weights(
    ctx: DriverContext, names: Sequence[str], values: np.ndarray, where: str = "keys"
) -> np.ndarray:
    """Curve values ``[F, C]`` named ``region`` or ``region:state`` -> weights ``[F, R, K]``."""
    f = values.shape[0]
    per_region = np.zeros((f, len(ctx.regions)), np.float64)
    per_cell = np.zeros((f, len(ctx.regions), ctx.weight_states), np.float64)
    has_cell = np.zeros((len(ctx.regions), ctx.weight_states), bool)
    for j, n in enumerate(names):
        r, k = _target_index(ctx, n, f"{where}.{n}")
        if k is None:
            per_region[:, r] += values[:, j]
        else:
            kk = 0 if ctx.policy == "signed" else k
            per_cell[:, r, kk] += values[:, j]
            has_cell[r, kk] = True
    w = ctx.spread(per_region).astype(np.float64)
    w = np.where(has_cell[None], w + per_cell, w)
    return w.astype(np.float32)


@register("curves")
def curves_driver(
    ctx: DriverContext, spec: Mapping[str, Any], times: np.ndarray | None
) -> DriverResult:
    keys, interp, notes = load_keys(ctx, spec)
    fps = float(spec.get("fps", ctx.fps))
    names: list[str] = []
    cols: list[np.ndarray] = []
    gltf = None
    clip = None
    if "file" in spec and is_gltf(spec["file"]):
        *gltf, clip = morph_clip_animation(
            ctx, resolve(ctx, str(spec["file"])), times, fps, spec.get("clip")
        )
        times = gltf[0]
    if not keys and gltf is None:
        raise spec_problem(ctx, "curves driver needs 'keys' or a 'file'", "keys")
    if times is None:
        times = frame_times(*keys_range(keys), fps)
    if gltf is not None:
        _, tnames, tw = gltf
        skipped = [n for n in tnames if n.partition(":")[0] not in ctx.regions]
        if skipped:
            notes.append(f"glTF morph targets that are not regions were ignored: {skipped}")
        for j, n in enumerate(tnames):
            if n not in skipped:
                names.append(n)
                cols.append(tw[:, j])
        if not names and not keys:
            raise spec_problem(ctx, "no glTF morph target is named after a region", "file")
    for n in keys:
        names.append(n)
        cols.append(sample_keys(keys, [n], times, interp)[:, 0])
    values = np.stack(cols, axis=1)
    w = curves_to_weights(ctx, names, values)
    states = ("signed",) if ctx.policy == "signed" else ctx.states
    moving = [n for n, col in zip(names, values.T) if np.any(col != 0)]
    source: dict[str, Any] = {"from": "file" if clip is not None else "keys"}
    if clip is not None:
        source["clip"] = clip.to_json()
    source.update(inputs=list(dict.fromkeys(names)), moving=list(dict.fromkeys(moving)))
    return DriverResult(
        "curves", np.asarray(times), w, ctx.regions, states, notes=notes, source=source
    )
