"""Repairs of source data the glTF spec forbids, so the output passes the Khronos validator.

Each repair adds a corrected accessor (or bufferView) and points the user at it; the source
accessor stays in the document unchanged when something else still uses it. Each returns notes
that say exactly what changed, for the convert report.

- :func:`normalize_skin_weights`: ``WEIGHTS_n`` rows whose sum is not 1 (the spec requires a
  linear sum of 1; RobotExpressive's hands sum to 1.039) are divided by their sum (float
  accessors only; rows of zeros bind to the first joint with weight 1).
- :func:`unstride_animation_and_skin_accessors`: animation sampler and inverse-bind-matrix
  accessors must not live in a strided bufferView; they get a tightly packed copy (same values).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from wrinklepipe.gltf.document import ARRAY_BUFFER, Document
from wrinklepipe.names import plural

#: Largest |sum - 1| left alone (float32 rounding of a normalised row stays far below).
WEIGHT_SUM_TOLERANCE = 1e-6


def normalize_skin_weights(doc: Document) -> list[str]:
    """Renormalise the float ``WEIGHTS_n`` sets of every primitive whose rows do not sum to 1."""
    notes: list[str] = []
    done: dict[tuple[int, ...], tuple[int, ...]] = {}
    for ref in doc.primitives():
        attrs = doc.primitive(ref).get("attributes", {})
        names = sorted(
            (k for k in attrs if k.startswith("WEIGHTS_") and k[8:].isdigit()),
            key=lambda k: int(k[8:]),
        )
        if not names:
            continue
        ids = tuple(attrs[k] for k in names)
        if ids in done:
            for k, new in zip(names, done[ids]):
                attrs[k] = new
            continue
        accs = [doc.array("accessors")[i] for i in ids]
        if any(a.get("componentType") != 5126 for a in accs):
            continue  # normalised integer weights: left as they are
        w = np.concatenate([doc.accessor(i).astype(np.float64) for i in ids], axis=1)
        total = w.sum(axis=1)
        bad = np.abs(total - 1.0) > WEIGHT_SUM_TOLERANCE
        if not bad.any():
            done[ids] = ids
            continue
        fixed = w.copy()
        ok = bad & (total > 0)
        fixed[ok] /= total[ok, None]
        zero = bad & (total <= 0)
        fixed[zero] = 0.0
        fixed[zero, 0] = 1.0
        fixed32 = fixed.astype(np.float32)
        new = tuple(
            doc.add_accessor(fixed32[:, 4 * j : 4 * j + 4], ARRAY_BUFFER) for j in range(len(ids))
        )
        for k, a in zip(names, new):
            attrs[k] = a
        done[ids] = new
        worst = float(np.max(np.abs(total[bad] - 1.0)))
        notes.append(
            f"{ref.pointer}: {int(bad.sum())} of {len(w)} skin weight rows did not sum to 1 "
            f"(off by up to {worst:.4g}); renormalised into new accessors "
            f"{', '.join(map(str, new))} (source accessors {', '.join(map(str, ids))} unchanged)"
        )
    return notes


def unstride_animation_and_skin_accessors(doc: Document) -> list[str]:
    """Give animation-sampler and inverse-bind-matrix accessors in strided views their own
    tightly packed bufferView (same bytes per element, no stride)."""
    users: list[tuple[str, int]] = []
    for ai, anim in enumerate(doc.array("animations")):
        for si, s in enumerate(anim.get("samplers", [])):
            for k in ("input", "output"):
                if isinstance(s.get(k), int):
                    users.append((f"/animations/{ai}/samplers/{si}/{k}", s[k]))
    for si, skin in enumerate(doc.array("skins")):
        if isinstance(skin.get("inverseBindMatrices"), int):
            users.append((f"/skins/{si}/inverseBindMatrices", skin["inverseBindMatrices"]))
    accs = doc.array("accessors")
    fixed: dict[int, int] = {}
    for _, ai in users:
        if ai in fixed or not 0 <= ai < len(accs) or "bufferView" not in accs[ai]:
            continue
        view = doc.array("bufferViews")[accs[ai]["bufferView"]]
        if not view.get("byteStride"):
            continue
        values = doc.accessor(ai, normalize=False)
        a: dict[str, Any] = accs[ai]
        a["bufferView"] = doc.add_view(np.ascontiguousarray(values).tobytes())
        a.pop("byteOffset", None)
        fixed[ai] = a["bufferView"]
    if not fixed:
        return []
    return [
        f"{plural(len(fixed), 'animation / inverse-bind-matrix accessor')} read from strided "
        "bufferViews "
        "(the spec forbids a byteStride there) were given tightly packed copies (same values)"
    ]


def repair(doc: Document) -> list[str]:
    """Every repair above, in order; the notes say what changed."""
    return normalize_skin_weights(doc) + unstride_animation_and_skin_accessors(doc)
