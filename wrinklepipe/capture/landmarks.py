"""Landmark files as an artist exports them from any tool: JSON or CSV, pixels or UV.

Accepted JSON shapes (``x``/``u`` to the right, ``y``/``v`` down, origin at the top-left corner):

- ``[[x, y], ...]``
- ``{"points": [[x, y], ...], "names": [...], "space": "pixels" | "uv"}``
- ``{"points": {"name": [x, y], ...}}`` or a top-level ``{"name": [x, y], ...}``
- ``[{"name": "...", "x": 1, "y": 2}, ...]``

CSV: one landmark per line, ``x,y`` or ``name,x,y``; a first line that is not numeric is a header
(``u,v`` in it means UV space); lines starting with ``#`` are comments. ``space = "uv"`` means
coordinates in [0, 1] of the image (glTF convention, v down), scaled by the image size on use.

When both sets of a pair carry names they are paired by name; otherwise by order.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wrinklepipe.capture.warp import is_collinear
from wrinklepipe.errors import InputError, Problem, input_error
from wrinklepipe.io.json_safe import loads_json
from wrinklepipe.names import noun, plural

MIN_LANDMARKS = 3


@dataclass(frozen=True)
class Landmarks:
    """Points ``[N, 2]`` (float64), optional names, the space they were given in, the file."""

    points: np.ndarray
    names: tuple[str, ...] | None = None
    space: str = "pixels"
    file: str = ""

    def to_pixels(self, width: int, height: int) -> Landmarks:
        """The same landmarks in pixels of an image of the given size."""
        if self.space == "pixels":
            return self
        pts = self.points * np.array([width, height], np.float64)
        return Landmarks(pts, self.names, "pixels", self.file)


def _number(value: object, file: Path, key: str) -> float:
    try:
        out = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise input_error(file, f"expected a number, got {value!r}", key) from None
    if not np.isfinite(out):
        raise input_error(file, f"coordinate is not finite ({value!r})", key)
    return out


def _pair(value: object, file: Path, key: str) -> tuple[float, float]:
    if isinstance(value, dict):
        x = value.get("x", value.get("u"))
        y = value.get("y", value.get("v"))
        return _number(x, file, key + "/x"), _number(y, file, key + "/y")
    if not isinstance(value, (list, tuple)) or len(value) < 2:
        raise input_error(file, f"expected [x, y], got {value!r}", key)
    return _number(value[0], file, key + "/0"), _number(value[1], file, key + "/1")


def _from_json(data: object, file: Path) -> Landmarks:
    space = "pixels"
    names: list[str] | None = None
    pts: list[tuple[float, float]] = []
    if isinstance(data, dict) and "points" in data:
        space = str(data.get("space", "pixels"))
        body = data["points"]
        if isinstance(data.get("names"), list):
            names = [str(n) for n in data["names"]]
    else:
        body = data
    if isinstance(body, dict):
        names = [str(k) for k in body]
        pts = [_pair(v, file, f"/{k}") for k, v in body.items()]
    elif isinstance(body, list):
        pts = [_pair(v, file, f"/{i}") for i, v in enumerate(body)]
        if body and all(isinstance(v, dict) and "name" in v for v in body):
            names = [str(v["name"]) for v in body]
    else:
        raise input_error(file, "expected a list of [x, y] points or an object of named points")
    if names is not None and len(names) != len(pts):
        raise input_error(file, f"{len(names)} names for {len(pts)} points", "/names")
    return _finish(pts, names, space, file)


def _from_csv(text: str, file: Path) -> Landmarks:
    rows = [r for r in csv.reader(io.StringIO(text)) if r and not r[0].strip().startswith("#")]
    rows = [[c.strip() for c in r if c.strip() != ""] for r in rows]
    rows = [r for r in rows if r]
    space = "pixels"
    if rows:
        try:
            float(rows[0][-1])
        except ValueError:
            header = [c.lower() for c in rows[0]]
            if "u" in header or "v" in header:
                space = "uv"
            rows = rows[1:]
    names: list[str] | None = None
    pts = []
    for i, r in enumerate(rows):
        key = f"line {i + 1}"
        if len(r) >= 3:
            names = (names or []) + [r[0]]
            pts.append((_number(r[1], file, key), _number(r[2], file, key)))
        elif len(r) == 2:
            pts.append((_number(r[0], file, key), _number(r[1], file, key)))
        else:
            raise input_error(file, f"expected 'x,y' or 'name,x,y', got {','.join(r)!r}", key)
    if names is not None and len(names) != len(pts):
        raise input_error(file, "some lines have a name and some do not")
    return _finish(pts, names, space, file)


def _finish(pts: list, names: list[str] | None, space: str, file: Path) -> Landmarks:
    if space not in ("pixels", "uv"):
        raise input_error(file, f"unknown space {space!r}; expected 'pixels' or 'uv'", "/space")
    if names is not None and len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise input_error(file, f"duplicate landmark names: {', '.join(dup)}")
    arr = np.asarray(pts, np.float64).reshape(-1, 2)
    return Landmarks(arr, tuple(names) if names is not None else None, space, str(file))


def read_landmarks(path: str | Path) -> Landmarks:
    """Read a landmark file (``.json`` or ``.csv``/``.txt``); raise :class:`InputError` if bad."""
    file = Path(path)
    if not file.exists():
        raise input_error(file, "file not found")
    try:
        text = file.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise input_error(file, f"cannot read landmark file: {exc}") from None
    if file.suffix.lower() == ".json" or text.lstrip().startswith(("[", "{")):
        data = loads_json(text, file, "landmark JSON")
        return _from_json(data, file)
    return _from_csv(text, file)


def check_inside(lm: Landmarks, width: int, height: int, what: str) -> None:
    """Refuse landmarks outside an image of ``width`` x ``height`` pixels (all listed at once)."""
    p = lm.points
    bad = np.nonzero((p[:, 0] < 0) | (p[:, 0] > width) | (p[:, 1] < 0) | (p[:, 1] > height))[0]
    if len(bad):
        shown = ", ".join(
            f"{lm.names[i] if lm.names else '#' + str(i)} at ({p[i, 0]:.1f}, {p[i, 1]:.1f})"
            for i in bad[:5]
        )
        more = f" and {len(bad) - 5} more" if len(bad) > 5 else ""
        raise input_error(
            lm.file,
            f"{plural(len(bad), 'landmark')} outside the {what} ({width} x {height} px): "
            f"{shown}{more}",
        )


def pair(a: Landmarks, b: Landmarks) -> tuple[np.ndarray, np.ndarray]:
    """Corresponding points of two sets: by name when both are named, else by order.

    Checks the counts, the minimum of 3 and that the points are not collinear.
    """
    if a.names is not None and b.names is not None:
        missing_b = [n for n in a.names if n not in b.names]
        missing_a = [n for n in b.names if n not in a.names]
        if missing_a or missing_b:
            probs = []
            if missing_b:
                probs.append(
                    Problem(
                        b.file, f"missing {noun(len(missing_b), 'landmark')} {', '.join(missing_b)}"
                    )
                )
            if missing_a:
                probs.append(
                    Problem(
                        a.file, f"missing {noun(len(missing_a), 'landmark')} {', '.join(missing_a)}"
                    )
                )
            raise InputError(probs)
        idx = [b.names.index(n) for n in a.names]
        pa, pb = a.points, b.points[idx]
    else:
        if len(a.points) != len(b.points):
            raise input_error(
                b.file,
                f"has {len(b.points)} landmarks but {Path(a.file).name} has {len(a.points)}; "
                "the two sets must correspond one to one",
            )
        pa, pb = a.points, b.points
    for lm in (a, b):
        if len(lm.points) < MIN_LANDMARKS:
            raise input_error(
                lm.file,
                f"only {plural(len(lm.points), 'landmark')}; a thin-plate warp needs at least "
                f"{MIN_LANDMARKS} that are not on one line",
            )
    for lm, pts in ((a, pa), (b, pb)):
        uniq, counts = np.unique(np.round(pts, 6), axis=0, return_counts=True)
        if (counts > 1).any():
            x, y = uniq[np.argmax(counts > 1)]
            raise input_error(lm.file, f"two landmarks share the position ({x:g}, {y:g})")
        if is_collinear(pts):
            raise input_error(lm.file, "landmarks lie on one line; the warp needs them to span 2-D")
    return pa, pb
