"""The rule catalogue: every code ``validate-asset`` can report, in one place.

Codes are stable (``WP-<AREA>-<NNN>``); a code is never reused for a different check. The docs
table ``docs/ISSUES.md`` is generated from :data:`RULES` (``python -m
wrinklepipe.validate docs/ISSUES.md``), as the Khronos glTF-Validator's ISSUES.md is;
a test fails when the file is stale.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

SEVERITIES = ("error", "warning", "info")


@dataclass(frozen=True)
class Rule:
    code: str
    severity: str  # default severity (a config file may change it)
    title: str
    description: str
    fix: str


@dataclass
class Issue:
    """One finding: a rule code, where, what, and what to do about it."""

    code: str
    message: str
    pointer: str
    severity: str = ""
    fix: str = ""
    data: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "code": self.code,
            "severity": self.severity,
            "message": self.message,
            "pointer": self.pointer,
            "fix": self.fix,
        }
        if self.data:
            out["data"] = self.data
        return out


AREAS = {
    "LOAD": "Container and declarations",
    "MAP": "Normal and wrinkle maps",
    "MASK": "Region masks and the channel table",
    "WGT": "Weights and drivers",
    "MESH": "Mesh, tangents, vertex IDs, morph targets",
    "TEX": "Texture formats, compression and footprint",
    "RND": "Render pass (GPU vs numpy reference)",
    "FID": "Fidelity: the shipped asset against the full-resolution source",
    "COL": "Colour states: colour maps against their base colour",
    "USD": "USD composition: sublayers, references, payloads",
}

RULES: tuple[Rule, ...] = (
    # --- LOAD
    Rule(
        "WP-LOAD-001",
        "error",
        "Unknown encoding or policy",
        "The asset declares an encoding or policy the wrinkle model does not define, or a policy "
        "whose state count does not fit (``signed`` needs exactly two states).",
        "Declare one of the encodings pd, diff, full, composite and one of the policies clamp01, "
        "signed, additive, renormalize, lerp.",
    ),
    Rule(
        "WP-LOAD-002",
        "error",
        "State without a texture",
        "A declared wrinkle state has no shipped texture, or state textures differ in size or "
        "format (the shader samples them as one texture array).",
        "Ship one texture per state, all of one size and format.",
    ),
    Rule(
        "WP-LOAD-003",
        "error",
        "Nothing can wrinkle",
        "The asset declares no wrinkle states or no regions, so no weight can ever show.",
        "Declare at least one state with its map and one region with its mask.",
    ),
    # --- MAP
    Rule(
        "WP-MAP-001",
        "error",
        "NaN or non-unit normals",
        "Texels of a three-channel normal map decode to NaN or to a vector whose length is off "
        "1 by more than the tolerance (0.05 for 8-bit, quantisation included).",
        "Renormalise the map before quantising (encode-normals does).",
    ),
    Rule(
        "WP-MAP-002",
        "error",
        "Normals pointing into the surface",
        "Texels of a tangent-space normal map with z < 0 (after decode).",
        "Repair with z = |z| and renormalise, or fix the bake's cage.",
    ),
    Rule(
        "WP-MAP-003",
        "error",
        "Green-convention mismatch",
        "The map is not integrable under the declared green convention but is under the other "
        "one (curl test on the slopes): the green channel is flipped (DirectX vs OpenGL).",
        "Flip the green channel, or declare the convention the map was baked in.",
    ),
    Rule(
        "WP-MAP-004",
        "error",
        "PD slopes outside the recorded cone",
        "More than the allowed fraction of a pd map's texels sit at the edge of the recorded "
        "scale s (|d| >= s): their slopes were clipped, flattening the deepest wrinkles.",
        'Record a larger pd_scale (pd_scale = "auto" picks a power of two covering 99.9%).',
    ),
    Rule(
        "WP-MAP-005",
        "error",
        "Difference map bias is off",
        "Where no region is active a difference map must store 0.5 (no change); its median "
        "there is off by more than 2/255, so the face shifts even at zero weight.",
        "Re-encode with D = 0.5 + 0.5 (W - B) from the same base that ships.",
    ),
    Rule(
        "WP-MAP-006",
        "error",
        "Content does not match the declared encoding",
        "Decoded under the declared encoding the state is far from the source, while another "
        "encoding explains it (e.g. a diff map declared as pd).",
        "Declare the encoding the map was written with, or re-encode it.",
    ),
    Rule(
        "WP-MAP-007",
        "warning",
        "Problem texels in a source map",
        "Reading a source normal map found texels that are not unit length (by more than the "
        "reader's tolerance) or point below the surface (z < 0); they were renormalised to be "
        "blended and stored, so the shipped map differs from the file there.",
        "Re-bake or renormalise the source map, or ask for the repair explicitly.",
    ),
    # --- MASK
    Rule(
        "WP-MASK-001",
        "error",
        "Mask values outside [0, 1]",
        "A region mask holds NaN or values below 0 or above 1.",
        "Clamp the mask to [0, 1] (pack-masks does).",
    ),
    Rule(
        "WP-MASK-002",
        "error",
        "Overlapping masks under a policy that does not clamp",
        "Masks sum above 1 where the policy is additive, so overlapping regions double the "
        "wrinkle.",
        "Make the masks a partition of unity, or use policy clamp01 or renormalize.",
    ),
    Rule(
        "WP-MASK-003",
        "warning",
        "Region covers nothing",
        "A region's mask is zero everywhere (below 1/255), so its weight never shows.",
        "Paint the region, or remove it and its weights.",
    ),
    Rule(
        "WP-MASK-004",
        "error",
        "Channel table does not match the packed textures",
        "A channel-table entry names a missing texture or channel, two regions share a slot, a "
        "region has no entry, or the packed channel holds another region's mask (swapped "
        "channels).",
        "Rebuild the table with pack-masks, or fix the entry the message names.",
    ),
    Rule(
        "WP-MASK-005",
        "error",
        "Mask painted on the wrong side",
        "A region declared left (the character's left, +X) has most of its mask on the right, "
        "or the other way round.",
        "Mirror the mask, or fix the region's side.",
    ),
    Rule(
        "WP-MASK-006",
        "warning",
        "Region side contradicts its name",
        "A region whose name ends in _L / _R (or _left / _right) has another side, often center "
        "because ``side`` was left out, so the side check (WP-MASK-005) does not look at it.",
        "Set ``side`` to the side the name says (left is the character's left), or rename it.",
    ),
    # --- WGT
    Rule(
        "WP-WGT-001",
        "error",
        "Weight outside the policy's range",
        "An expression or driver weight lies outside the range the policy accepts "
        "(wrinklepipe.model.POLICY_WEIGHT_RANGE).",
        "Scale the weights into the range, or pick the policy they were authored for.",
    ),
    Rule(
        "WP-WGT-002",
        "error",
        "Expression names an unknown region",
        "An expression row weights a region that does not exist in the asset.",
        "Rename the region in the expression table or add the region.",
    ),
    Rule(
        "WP-WGT-003",
        "error",
        "Per-vertex weights jump across a UV seam",
        "Twins of a UV seam (same position, split for their UVs) carry different per-vertex "
        "weights, so dynamic wrinkles show a seam.",
        "Smooth per-vertex weights over vertex IDs (Oat), not over render vertices.",
    ),
    Rule(
        "WP-WGT-004",
        "error",
        "No pose of any driver activates a region (dead rig)",
        "Every frame of every driver (and the expression table, when it is played) leaves every "
        "region at weight 0, so no wrinkle ever shows: a blend-shape driver reading a clip whose "
        "morph weights are all 0, curves of zeros, rows naming shapes that never move. One "
        "message names each driver, why it gives nothing (the clip, the inputs that stay 0) and "
        "the regions; the per-region, per-state and per-driver rules are not repeated.",
        'Drive the regions: name the clip that moves the blend shapes (clip = "..." in the '
        "driver's table), key the curves, or fix the rows' inputs.",
    ),
    Rule(
        "WP-WGT-005",
        "warning",
        "A region no pose activates",
        "No frame of any driver (nor the expression table, when played) gives this region a "
        "weight, while others are driven: its wrinkles never show.",
        "Add the region to a driver's rows, keys or expressions, or remove it.",
    ),
    Rule(
        "WP-WGT-006",
        "warning",
        "A state no pose reaches",
        "No pose activates this wrinkle state: no driven region gives it a positive weight "
        "(the regions' ``states`` leave it out, or only negative weights reach it).",
        "Let a driven region drive the state, or ship without it.",
    ),
    Rule(
        "WP-WGT-007",
        "warning",
        "Driver clip chosen implicitly",
        "A driver reads a glTF file with several animations that drive morph weights and the "
        "manifest names none: the tool took the first that moves the driver's inputs (else the "
        "first); the message says which and how many there were.",
        'Name the clip in the driver\'s table: clip = "Name" (or its index).',
    ),
    Rule(
        "WP-WGT-008",
        "info",
        "Expression table and driver curves both present",
        "The asset has an expression table and drivers that are not an expressions driver: the "
        "drivers' curves drive the wrinkles and the poses judged; the table ships for engines "
        "but is not played. Said once.",
        "Add an expressions driver to play the table, or leave it for engines that read it.",
    ),
    Rule(
        "WP-WGT-009",
        "warning",
        "A blend-shape driver whose inputs never move",
        "The blend shapes a blendshapes driver's rows read stay 0 in every frame of its clip or "
        "keys (for a file: and in every clip of it), while another driver keeps the rig alive: "
        "this driver never adds a wrinkle.",
        'Name a clip that moves them (clip = "..."), or fix the rows\' inputs.',
    ),
    # --- MESH
    Rule(
        "WP-MESH-001",
        "error",
        "Missing tangents",
        "The mesh carries no tangents: engines generate their own and the normal maps no longer "
        "match the bake.",
        "Ship MikkTSpace tangents (explicit TANGENT attribute).",
    ),
    Rule(
        "WP-MESH-002",
        "error",
        "Tangents are not MikkTSpace",
        "Tangents are not unit, not orthogonal to the normal, have |w| != 1, or disagree with "
        "the UV gradient direction or handedness of their triangles.",
        "Regenerate tangents with MikkTSpace after the last UV or topology change.",
    ),
    Rule(
        "WP-MESH-003",
        "error",
        "UV-seam twins have different vertex IDs",
        "Render vertices at one position (split for UVs) must share one spatial-hash ID.",
        "Recompute vertex IDs from welded positions (vertex-ids).",
    ),
    Rule(
        "WP-MESH-004",
        "error",
        "Vertex IDs disagree with positions",
        "One vertex ID is used by vertices at different positions.",
        "Recompute vertex IDs from positions after the last edit.",
    ),
    Rule(
        "WP-MESH-005",
        "error",
        "Morph-target count mismatch",
        "The number of morph-target names, deltas and the targets a driver refers to disagree.",
        "Export one name per morph target and keep driver inputs in sync.",
    ),
    Rule(
        "WP-MESH-006",
        "warning",
        "No mesh or no UVs",
        "Without a mesh with UVs the render pass cannot run.",
        "Ship the mesh with TEXCOORD_0.",
    ),
    # --- TEX
    Rule(
        "WP-TEX-001",
        "error",
        "sRGB on a normal map",
        "A normal or wrinkle map is tagged sRGB; the GPU decodes it with the sRGB curve and "
        "every normal tilts.",
        "Tag normal maps as linear (raw / non-color data).",
    ),
    Rule(
        "WP-TEX-002",
        "error",
        "sRGB on a mask",
        "A mask texture is tagged sRGB, so mask values are remapped by the sRGB curve.",
        "Tag masks as linear (raw / non-color data).",
    ),
    Rule(
        "WP-TEX-003",
        "error",
        "BC texture size not a multiple of 4",
        "Block-compressed textures must be a multiple of 4 texels in both directions.",
        "Resize or pad to a multiple of 4 before compressing.",
    ),
    Rule(
        "WP-TEX-004",
        "error",
        "Texture data does not match its format",
        "Level 0 holds fewer bytes than its format and size need (truncated or mislabelled), or a "
        "block-compressed copy the asset lists (DDS or KTX2) cannot be read whole: a truncated "
        "or damaged container, a mip level missing or short, a level that does not decode to "
        "the texture it copies (or to the halving of the level above), copies of one texture "
        "that differ.",
        "Re-export the texture.",
    ),
    Rule(
        "WP-TEX-005",
        "error",
        "Shipping error over budget",
        "For some expression the wrinkled normal from the shipped (quantised, compressed, "
        "resampled) maps differs from the source by more than the budget (mean or p99 degrees).",
        "Use a better format (BC5 or 16-bit), a larger size, or loosen the budget.",
    ),
    Rule(
        "WP-TEX-006",
        "info",
        "Resolution above what the budget needs",
        "A state map at half its size still meets the budget for every expression; the extra "
        "bytes are wasted.",
        "Ship the map at half size (resolution.wrinkle).",
    ),
    Rule(
        "WP-TEX-007",
        "info",
        "Texture footprint",
        "Total bytes of the shipped textures (level 0), per role.",
        "",
    ),
    # --- RND
    Rule(
        "WP-RND-001",
        "error",
        "GPU render disagrees with the numpy reference",
        "The tangent-space normal buffer rendered by the shaders differs from the numpy model "
        "evaluated at the same rasterised UVs by more than 0.5 degrees mean or 2 degrees p99 "
        "(sampling the same shipped bytes).",
        "Check colour-space tags and formats of the textures; report a bug if they are right.",
    ),
    Rule(
        "WP-RND-002",
        "error",
        "Wrinkles where masks x weights are zero",
        "The render of an expression differs from neutral where the source masks times weights "
        "are zero.",
        "Check the mask packing, the channel table and the sides of the regions.",
    ),
    Rule(
        "WP-RND-003",
        "warning",
        "No wrinkle where masks x weights are active",
        "Where the source says a region with relief is fully active, the render does not "
        "change from neutral.",
        "Check the mask packing and the state textures.",
    ),
    Rule(
        "WP-RND-004",
        "warning",
        "Render pass skipped",
        "The render pass could not run (no OpenGL 3.3 context, no mesh, or unsupported layout).",
        "Install Mesa's EGL (llvmpipe) or run on a machine with a GPU.",
    ),
    Rule(
        "WP-RND-005",
        "error",
        "GPU colour vs the numpy colour model",
        "With colour states, the GPU's blended albedo or its lit colour differs from the numpy "
        "colour model of the same shipped texels (decoded from sRGB, sampled bilinearly, lit "
        "with the same light on the GPU's normal) by a p99 over 1 CIEDE2000 (the option "
        "gpu_max_p99_delta_e).",
        "A colour texture shipped or tagged as linear data (it must be sRGB), or a shader that "
        "blends colour in sRGB instead of linear light.",
    ),
    # --- FID
    Rule(
        "WP-FID-001",
        "error",
        "A pose is over the budget against the full-resolution source",
        "For one pose (an expression at full amount), the blend of the shipped, decoded "
        "textures differs from the blend of the source maps at full resolution by more than the "
        "budget (activation-weighted mean / p99 / max degrees inside the pose's active region; "
        "the compressed budget when base or states are block-compressed).",
        "Ship the states or masks larger, raise the PD scale if it clips, or use a better "
        "format; with every size on auto convert picks them.",
    ),
    Rule(
        "WP-FID-002",
        "warning",
        "A region is over the budget against the full-resolution source",
        "Inside one region (its mask, in the pose where it loses most) the shipped blend "
        "differs from the source's by more than the budget, even when the pose as a whole "
        "passes.",
        "Look at the region's heat map: a small crease lost at the shipped size, a mask edge.",
    ),
    Rule(
        "WP-FID-003",
        "warning",
        "The base is over the budget against the source base",
        "The shipped base alone, over the face (the mesh's UV footprint), differs from the "
        "source base by more than the budget.",
        "Ship the base larger or in a better format.",
    ),
    Rule(
        "WP-FID-004",
        "error",
        "The render is over the budget against the full-resolution source",
        "On the pixels where a pose is active, the GPU render of the shipped bytes differs from "
        "the numpy render of the full-resolution source (screen space) by more than the budget.",
        "See WP-FID-001; the render shows the loss as a viewer sees it.",
    ),
    Rule(
        "WP-FID-006",
        "error",
        "Base and states are not of one face (flipped or offset)",
        "Where every mask is zero a wrinkle state keeps the base's detail (it may add wrinkle "
        "relief there: the masks pick where it shows); here it keeps little of it, and does "
        "once the base is mirrored (V or U), its green channel flipped, or shifted by whole "
        "texels: the measured share of the base's detail is named both ways. A green flip the "
        "convention rule (WP-MAP-003) already reported is not said twice, and a mirror replaces "
        "that rule's report on the base.",
        "Flip or realign the map the message names and convert again.",
    ),
    Rule(
        "WP-FID-007",
        "warning",
        "States are of another face or bake",
        "Where every mask is zero the states keep little of the base's detail (the share of "
        "it they hold, by regression of their slopes on the base's) while differing from the "
        "base on a large part of the face, and no mirror, green flip or offset explains it: "
        "maps of another face or another bake. States that carry the base's detail and add "
        "relief everywhere are fine, and a base without detail gives no evidence: both are "
        "silent.",
        "Check that base and states are of one bake (the same face, UV layout and tangent frame).",
    ),
    Rule(
        "WP-FID-008",
        "error",
        "A pose's colour is over the colour budget against the full-resolution source",
        "For one pose, the colour blend of the shipped colour maps (sRGB texels decoded to "
        "linear light before filtering, the shipped masks) differs from the blend of the source "
        "colour maps at full resolution by more than the colour budget: activation-weighted "
        "mean / p99 CIEDE2000 inside the pose's active region (budget keys max_mean_delta_e, "
        "default 1, and max_p99_delta_e, default 2.3).",
        'Ship the colour states larger (resolution.color = "auto" picks the size within the '
        "budget) or in BC7 rather than BC1.",
    ),
    # --- COL
    Rule(
        "WP-COL-001",
        "error",
        "A colour map's size disagrees with the base colour",
        "A state's colour map is painted on the base colour's UV layout: its texture has the "
        "base colour's aspect (it may ship smaller). Another aspect is another UV layout.",
        "Paint the colour map on the base colour's layout, at its size.",
    ),
    Rule(
        "WP-COL-002",
        "error",
        "A colour map is flipped against the base colour",
        "Where every mask is zero a colour state should equal the base colour; here it differs "
        "by more than one just-noticeable difference on a large part of the face, and the base "
        "colour flipped in U or V explains most of it: the colour lands on the wrong part of "
        "the face.",
        "Flip the colour map (or the base colour) the message names and convert again.",
    ),
    Rule(
        "WP-COL-003",
        "warning",
        "A colour map differs from the base colour where every mask is zero",
        "Outside every mask a colour state differs from the base colour by more than one "
        "just-noticeable difference on a large part of the face, and no flip explains it: "
        "colour no mask ever shows, or a map painted on another UV layout.",
        "Paint the state's colour over the base colour, changed only where the regions that "
        "drive it show.",
    ),
    Rule(
        "WP-COL-004",
        "warning",
        "A colour state never changes the colour",
        "Under the masks of the regions that drive it, the state's colour map is within 0.5 "
        "CIEDE2000 of the base colour everywhere: it costs a texture and changes nothing "
        "visible (the base colour given as the state's colour map?).",
        "Give the state its own colour map (paler where the skin stretches, flushed where it "
        "compresses), or drop its color key.",
    ),
    # --- USD
    Rule(
        "WP-USD-001",
        "error",
        "Missing sublayer",
        "A layer of the USD stage names a sublayer that cannot be opened (not found, or not a "
        "layer): USD skips it, so everything it holds is missing from the stage.",
        "Fix the sublayer path (relative to the layer that names it) or remove the entry.",
    ),
    Rule(
        "WP-USD-002",
        "error",
        "Sublayer cycle",
        "The sublayers of the stage form a cycle (a layer reaches itself through its "
        "sublayers): USD drops the repeated layer.",
        "Remove the sublayer entry that leads back to a layer already in the stack.",
    ),
    Rule(
        "WP-USD-003",
        "error",
        "Missing reference or payload",
        "A reference or payload names a layer that cannot be opened, or a prim that the layer "
        "does not hold: the prim composes without it.",
        "Fix the asset path (relative to the layer that names it) or the target prim path.",
    ),
    Rule(
        "WP-USD-004",
        "error",
        "Reference or payload cycle",
        "References or payloads form a cycle (a prim reaches itself through its arcs): USD "
        "drops the arc that closes it.",
        "Remove the arc that leads back to a prim already in the chain.",
    ),
    Rule(
        "WP-USD-005",
        "warning",
        "Other composition error",
        "USD reported another composition error for the stage (a permission, a relocation, "
        "an inconsistent property type, a bad layer offset, ...).",
        "Read the message; fix the layer it names.",
    ),
    Rule(
        "WP-USD-006",
        "warning",
        "USD diagnostic while opening the stage",
        "USD posted a warning while opening the stage that is not a composition error (it is "
        "reported here in one line instead of being printed).",
        "Read the message; fix the layer it names.",
    ),
)

RULES_BY_CODE: dict[str, Rule] = {r.code: r for r in RULES}


def make_issue(code: str, message: str, pointer: str, fix: str = "", **data: Any) -> Issue:
    """An issue for ``code`` with the catalogue's severity and default fix."""
    rule = RULES_BY_CODE[code]
    return Issue(code, message, pointer, rule.severity, fix or rule.fix, dict(data))
