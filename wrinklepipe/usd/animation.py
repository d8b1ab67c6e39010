"""The glTF source's animations in its USD: one UsdSkel SkelAnimation per clip, chosen by a
variant set.

Every glTF animation (a clip) whose channels move nodes (``translation`` / ``rotation`` /
``scale``) or morph weights (``weights`` of a node whose mesh is bound to a Skeleton) becomes
a SkelAnimation below ``Scene/Animations``: ``joints`` = the animated
joints (the others keep their rest transforms), their transforms time-sampled in the
skeleton's convention (a root joint's includes its non-joint ancestors at rest),
``blendShapes`` / ``blendShapeWeights`` the animated targets (names made USD identifiers, as
the meshes' ``skel:blendShapes``). Skeletons with the same joints share one animation.

``Scene`` gets the variant set ``animation``: one variant per clip (its name made a USD
identifier, unique) and, when convert's weight curve drives morph targets, ``wrinkle`` (the
first curve's morph weights; selected by default, as the material's ``wrinkle:weights`` play
that curve), else the first clip selected. Each variant sets the skeletons'
``skel:animationSource``.

Times: seconds x the stage's ``timeCodesPerSecond``; samples at every key of the clip's
channels (USD interpolates linearly and slerps quaternions, as glTF's LINEAR does);
CUBICSPLINE channels are sampled besides at every frame of the stage's rate, STEP channels get
a second sample 1 ms before each key (held values). The stage's ``endTimeCode`` is extended to
the longest clip (the wrinkle weights hold their last value after their curve).

Nodes that are no joints but move (an animated prop, a character's root object): their Xform's
transform op gets its value from the variants only (a local value would be stronger than any
variant's samples): every variant authors the rest matrix, the clips that move it time samples
too; a joint below such a node takes its motion into its skeleton-space transform (a root
joint through its ancestors, a joint below non-joint nodes relative to its joint parent).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wrinklepipe.geometry.keyframes import sample_channel_at
from wrinklepipe.gltf.animation import Channel, read_channels
from wrinklepipe.gltf.document import Document
from wrinklepipe.gltf.primitive import node_matrix, trs_matrices  # the one glTF TRS
from wrinklepipe.names import noun, plural, unique_name
from wrinklepipe.usd.looks import gf_matrix

#: The variant that plays convert's weight curve (morph weights) on the wrinkled meshes.
WRINKLE_VARIANT = "wrinkle"
STEP_LEAD = 1e-3  # seconds: the sample before a STEP key that holds the previous value


@dataclass
class SkeletonInfo:
    """A Skeleton of the scene: its prim, joint nodes and tokens, and the morph-target meshes
    bound to it (``node -> target names``)."""

    skel: Any
    joints: list[int]
    tokens: list[str]
    morph_nodes: dict[int, list[str]] = field(default_factory=dict)


def _channels(doc: Document, a: int) -> list[Channel]:
    """The node and weights channels of animation ``a`` (:func:`wrinklepipe.gltf.animation.
    read_channels`, the one channel reader; a channel naming no node or sampler passed over)."""
    return read_channels(doc, a, strict=False)


def _times(channels: list[Channel], fps: float) -> np.ndarray:
    keys = [c.times for c in channels]
    for c in channels:
        if c.interpolation == "CUBICSPLINE" and len(c.times) > 1:
            keys.append(np.arange(c.times[0], c.times[-1], 1.0 / fps))
        if c.interpolation == "STEP":
            keys.append(c.times[1:] - STEP_LEAD)
    return np.unique(np.round(np.concatenate(keys) * fps, 6)) / fps


def _rest_trs(node: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return (
        np.asarray(node.get("translation", [0, 0, 0]), np.float64),
        np.asarray(node.get("rotation", [0, 0, 0, 1]), np.float64),
        np.asarray(node.get("scale", [1, 1, 1]), np.float64),
    )


def xform_animated_nodes(doc: Document) -> set[int]:
    """Nodes that are no joint of any skin and that some clip moves (translation / rotation /
    scale channels): their Xform's transform is authored by the variants."""
    joints = {int(j) for sk in doc.array("skins") for j in sk.get("joints", [])}
    return {
        int(c["target"]["node"])
        for a in doc.array("animations")
        for c in a.get("channels") or []
        if isinstance((c.get("target") or {}).get("node"), int)
        and c["target"].get("path") in ("translation", "rotation", "scale")
        and int(c["target"]["node"]) not in joints
    }


def add_animations(
    stage: Any,
    scene: Any,
    doc: Document,
    skeletons: list[SkeletonInfo],
    worlds: dict[int, np.ndarray],
    xforms: dict[int, Any],
    wrinkle: Any = None,
) -> list[str]:
    """Author the clips (see the module doc) below ``scene`` (the ``Scene`` prim path).
    ``xforms``: the Xform prim path of each node of :func:`xform_animated_nodes` in the scene
    (its transform op left without a value: every variant authors its rest matrix, a clip that
    moves it time samples too); ``wrinkle``: a callable ``(variant name) -> None`` authoring
    convert's morph-weight animation inside the ``wrinkle`` variant, or None. Returns notes."""
    from pxr import Tf, Usd, UsdGeom  # deferred: usd-core, USD only

    nodes = doc.array("nodes")
    parent = {int(c): i for i, n in enumerate(nodes) for c in n.get("children", [])}
    joint_nodes = {j for sk in skeletons for j in sk.joints}
    morph_nodes = {n for sk in skeletons for n in sk.morph_nodes}
    fps = stage.GetTimeCodesPerSecond()
    notes: list[str] = []
    clips = []  # (glTF name, its usable channels)
    skipped = 0
    for a in range(len(doc.array("animations"))):
        chans = _channels(doc, a)
        usable = [
            c
            for c in chans
            if (c.path == "weights" and c.node in morph_nodes)
            or (c.path != "weights" and (c.node in joint_nodes or c.node in xforms))
        ]
        skipped += len(chans) - len(usable)
        if usable:
            name = str(doc.array("animations")[a].get("name") or f"animation_{a}")
            clips.append((name, usable))
    if skipped:
        notes.append(
            f"USD: {plural(skipped, 'animation channel')} on nodes outside the scene (or weights "
            f"of meshes bound to no skeleton) {noun(skipped, 'is', 'are')} not carried (kept in "
            "the glTF)"
        )
    if not clips and wrinkle is None:
        for n, path in xforms.items():  # no variant set: the rest matrix, as authored
            _xform_op(stage, path).Set(gf_matrix(node_matrix(nodes[n])))
        return notes
    holder = scene.AppendChild("Animations")
    UsdGeom.Scope.Define(stage, holder)
    vset = stage.GetPrimAtPath(scene).GetVariantSets().AddVariantSet("animation")
    taken: set[str] = set()

    def variant_name(name: str) -> str:
        return unique_name(Tf.MakeValidIdentifier(name), taken)

    def rest_xforms() -> None:
        for n, path in xforms.items():
            _xform_op(stage, path).Set(gf_matrix(node_matrix(nodes[n])))

    if wrinkle is not None:
        variant_name(WRINKLE_VARIANT)
        vset.AddVariant(WRINKLE_VARIANT)
        vset.SetVariantSelection(WRINKLE_VARIANT)
        with vset.GetVariantEditContext():
            wrinkle(WRINKLE_VARIANT)
            rest_xforms()
        vset.ClearVariantSelection()
    first_clip = ""
    groups: dict[tuple[str, ...], list[SkeletonInfo]] = {}
    for sk in skeletons:
        groups.setdefault(tuple(sk.tokens), []).append(sk)
    ends = []
    for name, chans in clips:
        var = variant_name(name)
        first_clip = first_clip or var
        vset.AddVariant(var)
        vset.SetVariantSelection(var)
        times = _times(chans, fps)
        codes = times * fps
        ends.append(float(codes[-1]))
        by_node: dict[int, dict[str, Channel]] = {}
        for c in chans:
            by_node.setdefault(c.node, {})[c.path] = c
        local = _Locals(nodes, parent, worlds, by_node, times)
        with vset.GetVariantEditContext():
            rest_xforms()
            for n, path in xforms.items():
                if n in by_node:
                    op = _xform_op(stage, path)
                    mats = local.local(n)
                    for f, code in enumerate(codes):
                        op.Set(gf_matrix(mats[f]), Usd.TimeCode(float(code)))
            for g, (tokens, members) in enumerate(groups.items()):
                name = var if len(groups) == 1 else f"{var}_{g}"
                _skel_animation(stage, holder.AppendChild(name), tokens, members, by_node, local)
        vset.ClearVariantSelection()
    default = WRINKLE_VARIANT if wrinkle is not None else first_clip
    vset.SetVariantSelection(default)
    if ends and (not stage.HasAuthoredTimeCodeRange() or max(ends) > stage.GetEndTimeCode()):
        if not stage.HasAuthoredTimeCodeRange():
            stage.SetStartTimeCode(0.0)
        stage.SetEndTimeCode(max(ends))  # the timeline holds the longest clip too
    if clips:
        notes.append(
            f"USD: the {plural(len(clips), 'glTF animation')} "
            f"{noun(len(clips), 'is a SkelAnimation', 'are SkelAnimations')} (and time-sampled "
            f"Xforms), one variant each of the variant set 'animation' on {scene} "
            f"(selected: {default})"
        )
    return notes


def _skel_animation(
    stage: Any,
    path: Any,
    tokens: tuple[str, ...],
    members: list[SkeletonInfo],
    by_node: dict[int, dict[str, Channel]],
    local: _Locals,
) -> None:
    """One clip's SkelAnimation at ``path`` for the skeletons that share ``tokens``: the
    joints it moves (or a moving non-joint ancestor carries) and the blend-shape weights of
    their meshes, bound as each skeleton's animation source; nothing when the clip moves
    neither."""
    from pxr import Sdf, Tf, Usd, UsdSkel, Vt  # deferred: usd-core, USD only

    parent, times = local.parent, local.times
    codes = times * stage.GetTimeCodesPerSecond()
    first = members[0]
    in_skel = set(first.joints)

    moved = [  # animated joints, and those a moving non-joint ancestor carries
        k
        for k, j in enumerate(first.joints)
        if j in by_node
        or (
            parent.get(j) not in in_skel
            and local.moves(parent.get(j), _joint_parent(j, parent, in_skel))
        )
    ]
    shapes: list[str] = []
    weights: list[np.ndarray] = []
    for sk in members:
        for node, targets in sk.morph_nodes.items():
            c = by_node.get(node, {}).get("weights")
            if c is None:
                continue
            w = sample_channel_at(c.times, c.values, times, c.interpolation, "weights")
            for i, target in enumerate(targets[: w.shape[1]]):
                tok = Tf.MakeValidIdentifier(target)
                if tok not in shapes:
                    shapes.append(tok)
                    weights.append(w[:, i])
    if not moved and not shapes:
        return
    anim = UsdSkel.Animation.Define(stage, path)
    if moved:
        anim.CreateJointsAttr(Vt.TokenArray([tokens[k] for k in moved]))
        mats = np.empty((len(times), len(moved), 4, 4))
        for col, k in enumerate(moved):
            j = first.joints[k]
            up = _joint_parent(j, parent, in_skel)
            if up is None:  # a root: skeleton space (its ancestors' world)
                mats[:, col] = local.world(j)
            elif parent.get(j) == up:
                mats[:, col] = local.local(j)
            else:  # non-joint nodes between it and its joint parent
                mats[:, col] = np.linalg.inv(local.world(up)) @ local.world(j)
        for f, code in enumerate(codes):
            anim.SetTransforms(
                Vt.Matrix4dArray.FromNumpy(np.ascontiguousarray(mats[f].transpose(0, 2, 1))),
                Usd.TimeCode(float(code)),
            )
    if shapes:
        anim.CreateBlendShapesAttr(Vt.TokenArray(shapes))
        attr = anim.CreateBlendShapeWeightsAttr()
        table = np.stack(weights, 1).astype(np.float32)
        for f, code in enumerate(codes):
            attr.Set(Vt.FloatArray.FromNumpy(table[f]), Usd.TimeCode(float(code)))
    for sk in members:
        api = UsdSkel.BindingAPI(sk.skel.GetPrim())
        api.CreateAnimationSourceRel().SetTargets([Sdf.Path(path)])


def _xform_op(stage: Any, path: Any) -> Any:
    from pxr import UsdGeom  # deferred: usd-core, USD only

    return UsdGeom.Xformable(stage.GetPrimAtPath(path)).GetOrderedXformOps()[0]


def _joint_parent(j: int, parent: dict[int, int], in_skel: set[int]) -> int | None:
    up = parent.get(j)
    while up is not None and up not in in_skel:
        up = parent.get(up)
    return up


class _Locals:
    """Each node's local and world matrices ``[F, 4, 4]`` over a clip's times (the clip's
    channels where it has them, the node's rest TRS elsewhere)."""

    def __init__(self, nodes: list, parent: dict, worlds: dict, by_node: dict, times: np.ndarray):
        self.nodes, self.parent, self.rest_worlds = nodes, parent, worlds
        self.by_node, self.times = by_node, times
        self.locals: dict[int, np.ndarray] = {}
        self.worlds: dict[int, np.ndarray] = {}

    def local(self, n: int) -> np.ndarray:
        if n not in self.locals:
            got = self.by_node.get(n, {})
            f = len(self.times)
            if not any(p in got for p in ("translation", "rotation", "scale")):
                self.locals[n] = np.broadcast_to(node_matrix(self.nodes[n]), (f, 4, 4))
            else:
                t0, q0, s0 = _rest_trs(self.nodes[n])
                tr, ro, sc = (
                    sample_channel_at(c.times, c.values, self.times, c.interpolation, p)
                    if (c := got.get(p)) is not None
                    else np.repeat(rest[None], f, 0)
                    for p, rest in (("translation", t0), ("rotation", q0), ("scale", s0))
                )
                self.locals[n] = trs_matrices(tr, ro, sc)
        return self.locals[n]

    def world(self, n: int) -> np.ndarray:
        if n not in self.worlds:
            if not self.moves(n):  # nothing at or above it moves: the rest world
                rest = self.rest_worlds.get(n)
                if rest is None:
                    rest = node_matrix(self.nodes[n])
                self.worlds[n] = np.broadcast_to(rest, (len(self.times), 4, 4))
            else:
                p = self.parent.get(n)
                here = self.local(n)
                self.worlds[n] = here if p is None else self.world(p) @ here
        return self.worlds[n]

    def moves(self, n: int | None, stop: int | None = None) -> bool:
        """Whether ``n`` or an ancestor below ``stop`` is animated in the clip."""
        while n is not None and n != stop:
            if n in self.by_node:
                return True
            n = self.parent.get(n)
        return False
