"""ARKit's 52 blend shapes and a starting-point table from them to wrinkle regions.

The table is in the form MetaHuman's RigLogic uses for its conditional tables: rows
``(input, output, from, to, slope, cut)``; a row adds ``slope * x + cut`` to ``output`` when
``from < x <= to`` for its input weight ``x``; outputs are summed, then clamped to [0, 1].

**This is a starting point to tune, not a measured mapping.** It follows Jimenez et al.'s Table
1.1 where it can (raising the inner brows wrinkles the inner forehead; lowering the brows folds
the glabella and, with a negative weight, cancels the inner forehead as anger does in their
Fig. 1.5) and the usual anatomy elsewhere (nose sneer -> nose lines, cheek/eye squint -> crow's
feet, smile -> nasolabial folds, which ramp in late through two rows, lower-lip shrug -> chin).
ARKit's ``...Left`` is taken as the character's left (``_l``); mirror the rows if your capture
source reports the other way round. Rows whose output region an asset lacks are skipped (and
noted); rows whose input shape the mesh lacks are an error.
"""

from __future__ import annotations

#: ARKit's 52 blend-shape names (ARFaceAnchor.BlendShapeLocation raw values).
NAMES: tuple[str, ...] = (
    "eyeBlinkLeft",
    "eyeLookDownLeft",
    "eyeLookInLeft",
    "eyeLookOutLeft",
    "eyeLookUpLeft",
    "eyeSquintLeft",
    "eyeWideLeft",
    "eyeBlinkRight",
    "eyeLookDownRight",
    "eyeLookInRight",
    "eyeLookOutRight",
    "eyeLookUpRight",
    "eyeSquintRight",
    "eyeWideRight",
    "jawForward",
    "jawLeft",
    "jawRight",
    "jawOpen",
    "mouthClose",
    "mouthFunnel",
    "mouthPucker",
    "mouthLeft",
    "mouthRight",
    "mouthSmileLeft",
    "mouthSmileRight",
    "mouthFrownLeft",
    "mouthFrownRight",
    "mouthDimpleLeft",
    "mouthDimpleRight",
    "mouthStretchLeft",
    "mouthStretchRight",
    "mouthRollLower",
    "mouthRollUpper",
    "mouthShrugLower",
    "mouthShrugUpper",
    "mouthPressLeft",
    "mouthPressRight",
    "mouthLowerDownLeft",
    "mouthLowerDownRight",
    "mouthUpperUpLeft",
    "mouthUpperUpRight",
    "browDownLeft",
    "browDownRight",
    "browInnerUp",
    "browOuterUpLeft",
    "browOuterUpRight",
    "cheekPuff",
    "cheekSquintLeft",
    "cheekSquintRight",
    "noseSneerLeft",
    "noseSneerRight",
    "tongueOut",
)

Row = tuple[str, str, float, float, float, float]

#: (input, output, from, to, slope, cut). Outputs use the Jimenez zone names plus
#: ``crowsfeet_l/r`` and ``nasolabial_l/r``.
ROWS: tuple[Row, ...] = (
    ("browInnerUp", "forehead_inner_l", 0.0, 1.0, 1.0, 0.0),
    ("browInnerUp", "forehead_inner_r", 0.0, 1.0, 1.0, 0.0),
    ("browOuterUpLeft", "forehead_outer_l", 0.0, 1.0, 1.0, 0.0),
    ("browOuterUpRight", "forehead_outer_r", 0.0, 1.0, 1.0, 0.0),
    ("browDownLeft", "glabella", 0.0, 1.0, 0.6, 0.0),
    ("browDownRight", "glabella", 0.0, 1.0, 0.6, 0.0),
    ("browDownLeft", "forehead_inner_l", 0.0, 1.0, -0.8, 0.0),
    ("browDownRight", "forehead_inner_r", 0.0, 1.0, -0.8, 0.0),
    ("noseSneerLeft", "nose_l", 0.0, 1.0, 1.0, 0.0),
    ("noseSneerRight", "nose_r", 0.0, 1.0, 1.0, 0.0),
    ("cheekSquintLeft", "crowsfeet_l", 0.0, 1.0, 1.0, 0.0),
    ("cheekSquintRight", "crowsfeet_r", 0.0, 1.0, 1.0, 0.0),
    ("eyeSquintLeft", "crowsfeet_l", 0.0, 1.0, 0.5, 0.0),
    ("eyeSquintRight", "crowsfeet_r", 0.0, 1.0, 0.5, 0.0),
    # Smile folds ramp in late: 0.5 x up to x = 0.5, then 1.5 x - 0.5 (continuous at 0.25).
    ("mouthSmileLeft", "nasolabial_l", 0.0, 0.5, 0.5, 0.0),
    ("mouthSmileLeft", "nasolabial_l", 0.5, 1.0, 1.5, -0.5),
    ("mouthSmileRight", "nasolabial_r", 0.0, 0.5, 0.5, 0.0),
    ("mouthSmileRight", "nasolabial_r", 0.5, 1.0, 1.5, -0.5),
    ("mouthShrugLower", "chin", 0.0, 1.0, 1.0, 0.0),
)

#: The regions the rows drive.
REGIONS: tuple[str, ...] = tuple(dict.fromkeys(r[1] for r in ROWS))

PRESETS = {"arkit52": ROWS, "arkit": ROWS}

#: The face area each shape deforms (regions from blend shapes name their clusters after it):
#: the Jimenez zones where they apply, ``crowsfeet`` / ``nasolabial`` as the rows above, and
#: the usual anatomy elsewhere. ``tongueOut`` moves no skin (None).
AREAS: dict[str, str | None] = {
    **{f"eyeBlink{s}": "eyelid_upper" for s in ("Left", "Right")},
    **{f"eyeLookDown{s}": "eyelid_lower" for s in ("Left", "Right")},
    **{f"eyeLookIn{s}": "eyelid" for s in ("Left", "Right")},
    **{f"eyeLookOut{s}": "eyelid" for s in ("Left", "Right")},
    **{f"eyeLookUp{s}": "eyelid_upper" for s in ("Left", "Right")},
    **{f"eyeSquint{s}": "crowsfeet" for s in ("Left", "Right")},
    **{f"eyeWide{s}": "eyelid_upper" for s in ("Left", "Right")},
    "jawForward": "jaw",
    "jawLeft": "jaw",
    "jawRight": "jaw",
    "jawOpen": "jaw",
    "mouthClose": "lips",
    "mouthFunnel": "lips",
    "mouthPucker": "lips",
    "mouthLeft": "mouth_corner",
    "mouthRight": "mouth_corner",
    **{f"mouthSmile{s}": "nasolabial" for s in ("Left", "Right")},
    **{f"mouthFrown{s}": "mouth_corner" for s in ("Left", "Right")},
    **{f"mouthDimple{s}": "mouth_corner" for s in ("Left", "Right")},
    **{f"mouthStretch{s}": "mouth_corner" for s in ("Left", "Right")},
    "mouthRollLower": "lip_lower",
    "mouthRollUpper": "lip_upper",
    "mouthShrugLower": "chin",
    "mouthShrugUpper": "lip_upper",
    **{f"mouthPress{s}": "lips" for s in ("Left", "Right")},
    **{f"mouthLowerDown{s}": "lip_lower" for s in ("Left", "Right")},
    **{f"mouthUpperUp{s}": "lip_upper" for s in ("Left", "Right")},
    **{f"browDown{s}": "glabella" for s in ("Left", "Right")},
    "browInnerUp": "forehead_inner",
    **{f"browOuterUp{s}": "forehead_outer" for s in ("Left", "Right")},
    "cheekPuff": "cheek",
    **{f"cheekSquint{s}": "crowsfeet" for s in ("Left", "Right")},
    **{f"noseSneer{s}": "nose" for s in ("Left", "Right")},
    "tongueOut": None,
}
