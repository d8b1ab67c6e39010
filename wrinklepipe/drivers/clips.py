"""Which animation clip of a glTF a driver reads, and what it says about the choice.

A glTF may hold many animations (RobotExpressive has 14); a driver that names a file reads the
clip its ``clip`` key names (the animation's name, or its index), else one chosen here: the
only clip that drives morph weights, or, among several, the first whose weights move the
driver's inputs (the blend shapes its rows read), else the first. The choice is recorded
(:class:`ClipChoice`) so the report and the validator can say which clip drove the poses, that
it was chosen implicitly, and whether any clip of the file moves the inputs at all.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from wrinklepipe.drivers.base import MorphClip


@dataclass(frozen=True)
class ClipChoice:
    """Which clip a driver read from ``file`` and why (JSON for the report, the validator)."""

    file: str
    clip: str
    index: int
    clips: tuple[str, ...]  # every clip of the file that drives morph weights
    named: bool  # the manifest named it (``clip = ...``)
    inputs: tuple[str, ...]  # the driver's inputs (blend shapes its rows read)
    moving: tuple[str, ...]  # of those, the ones the chosen clip moves
    clips_moving: tuple[str, ...]  # the clips that move some input

    @property
    def implicit(self) -> bool:
        """Chosen by the tool among several clips (the manifest named none)."""
        return not self.named and len(self.clips) > 1

    def describe(self) -> str:
        """``clip 'Dance' of RobotExpressive.glb (the first of 14; none moves its inputs)``."""
        return describe_clip(self.to_json())

    def to_json(self) -> dict[str, Any]:
        return {
            "file": self.file,
            "clip": self.clip,
            "index": self.index,
            "clips": list(self.clips),
            "named": self.named,
            "inputs": list(self.inputs),
            "moving": list(self.moving),
            "clips_moving": list(self.clips_moving),
        }


def describe_clip(clip: Mapping[str, Any]) -> str:
    """:meth:`ClipChoice.describe` of its JSON (as the report and the validator hold it)."""
    clips = list(clip.get("clips", []))
    moving = list(clip.get("clips_moving", []))
    if clip.get("named"):
        how = "named in the manifest"
    elif len(clips) <= 1:
        how = "its only clip"
    elif moving and clip.get("clip") == moving[0]:
        how = f"chosen: the first of {len(clips)} clips that moves the inputs; {len(moving)} do"
    else:
        how = f"chosen: the first of {len(clips)} clips; none moves the inputs"
    return f"clip {clip.get('clip')!r} of {clip.get('file')} ({how})"


def choose_clip(
    clips: Sequence[MorphClip], want: str | int | None, inputs: Sequence[str], file: str
) -> tuple[MorphClip, ClipChoice]:
    """The clip to read (module doc) and the record of the choice. ``ValueError`` (naming the
    clips there are) when ``want`` names none of them or the file has none."""
    names = tuple(c.name for c in clips)
    if not clips:
        raise ValueError(f"no animation of {file} drives morph-target weights")
    moving_clips = tuple(c.name for c in clips if c.moving(inputs))
    if want is not None:
        hit = [
            c
            for c in clips
            if (isinstance(want, int) and not isinstance(want, bool) and c.index == want)
            or (isinstance(want, str) and c.name == want)
        ]
        if not hit:
            raise ValueError(
                f"clip {want!r} is not an animation of {file} that drives morph weights; "
                f"there are {len(names)}: " + ", ".join(repr(n) for n in names)
            )
        chosen = hit[0]
    elif moving_clips:
        chosen = next(c for c in clips if c.name == moving_clips[0])
    else:
        chosen = clips[0]
    return chosen, ClipChoice(
        file=file,
        clip=chosen.name,
        index=chosen.index,
        clips=names,
        named=want is not None,
        inputs=tuple(inputs),
        moving=chosen.moving(inputs),
        clips_moving=moving_clips,
    )
