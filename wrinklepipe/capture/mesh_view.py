"""The neutral face's normals in the photo's view, from the character's mesh.

The landmarks that map the neutral photo to texture space also define the camera: each texture
landmark (a UV) is a point on the mesh's surface, and its photo landmark is where the camera
saw that point. The camera is fitted to those 3-D / 2-D pairs and the mesh's normals are
rendered from it, at the photo's size, as the per-pixel neutral shape the capture stage needs
(the same as ``--neutral-normals``).

Camera model: **scaled orthographic** (a rotation, one scale, an image offset), the model of a
face photographed with a long lens from a few metres, the usual capture set-up: the light at
the camera then lights every point from the view direction, which is what the ratio image
assumes. Landmarks on a nearly flat patch leave the camera's tilt two-fold ambiguous (a plane
seen from +t or -t degrees projects alike); both twins (and the affine camera's nearest
rotation) are refined and the one with the lowest reprojection residual is kept; the residual
(pixels) is reported. On an exactly flat patch the twins fit equally well and the first is
kept: give landmarks off the plane too (nose, eyes, mouth corners), as a face has them.

Frames: world = the mesh's positions; camera frame +X right (photo columns), +Y up (against
the rows), +Z towards the camera; photo pixel ``(col, row)`` has its centre at ``+0.5``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from wrinklepipe.asset import Mesh


@dataclass(frozen=True)
class OrthoCamera:
    """``col = scale * (R X)_x + offset_x``, ``row = -scale * (R X)_y + offset_y``."""

    rotation: np.ndarray  # [3, 3] world -> camera frame
    scale: float  # photo pixels per world unit
    offset: np.ndarray  # [2] (col, row) of the world origin
    residual_px: float  # RMS reprojection error of the landmarks
    max_residual_px: float

    def project(self, points: np.ndarray) -> np.ndarray:
        """Photo pixels ``[N, 2]`` (col, row) of world points ``[N, 3]``."""
        c = np.asarray(points, np.float64) @ self.rotation.T
        return np.stack([self.scale * c[:, 0], -self.scale * c[:, 1]], axis=-1) + self.offset

    @property
    def view_deg(self) -> float:
        """Angle between the camera's view axis and the world +Z axis (degrees)."""
        return float(np.degrees(np.arccos(np.clip(self.rotation[2, 2], -1.0, 1.0))))


def vertex_normals(mesh: Mesh) -> np.ndarray:
    """The mesh's normals, or area-weighted face normals summed at the vertices."""
    if mesh.normals is not None:
        n = np.asarray(mesh.normals, np.float64)
    else:
        p = np.asarray(mesh.positions, np.float64)
        t = np.asarray(mesh.indices, np.int64)
        face = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
        n = np.zeros_like(p)
        for k in range(3):  # the three corners of every triangle at once
            np.add.at(n, t[:, k], face)
    length = np.linalg.norm(n, axis=-1, keepdims=True)
    return n / np.maximum(length, 1e-12)


def points_at_uv(mesh: Mesh, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The surface points ``[N, 3]`` at texture coordinates ``uv`` ``[N, 2]`` (glTF convention)
    and whether each lies on the layout (``[N]`` bool): the first triangle whose UV triangle
    holds the point, barycentric interpolation of its positions."""
    if mesh.uvs is None:
        raise ValueError("the mesh has no texture coordinates")
    q = np.asarray(uv, np.float64)
    t = np.asarray(mesh.indices, np.int64)
    tri_uv = np.asarray(mesh.uvs, np.float64)[t]  # [T, 3, 2]
    a = tri_uv[:, 0]
    e1 = tri_uv[:, 1] - a
    e2 = tri_uv[:, 2] - a
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    ok_tri = np.abs(det) > 1e-14
    inv = np.where(ok_tri, 1.0 / np.where(ok_tri, det, 1.0), 0.0)
    d = q[:, None, :] - a[None]  # [N, T, 2]
    b1 = (d[..., 0] * e2[:, 1] - d[..., 1] * e2[:, 0]) * inv
    b2 = (e1[:, 0] * d[..., 1] - e1[:, 1] * d[..., 0]) * inv
    b0 = 1.0 - b1 - b2
    eps = 1e-9
    inside = (b0 >= -eps) & (b1 >= -eps) & (b2 >= -eps) & ok_tri
    found = inside.any(axis=1)
    k = np.argmax(inside, axis=1)
    rows = np.arange(len(q))
    p = np.asarray(mesh.positions, np.float64)[t[k]]  # [N, 3, 3]
    w = np.stack([b0[rows, k], b1[rows, k], b2[rows, k]], axis=-1)
    return np.einsum("nk,nkc->nc", w, p), found


def _residuals(x: np.ndarray, world: np.ndarray, photo: np.ndarray) -> np.ndarray:
    r = Rotation.from_rotvec(x[:3]).as_matrix()
    c = world @ r.T
    s = np.exp(x[3])
    pred = np.stack([s * c[:, 0] + x[4], -s * c[:, 1] + x[5]], axis=-1)
    return (pred - photo).ravel()


def _plane_candidates(world: np.ndarray, target: np.ndarray) -> list[np.ndarray]:
    """The two scaled rotations (rows ``s r1``, ``s r2``, world frame) that project the points'
    best plane as the data's 2-D affine fit does: the weak-perspective twins of a plane.

    In the plane's basis ``(e1, e2)`` the fit is ``M (u, v)``; rows ``s r_i = (M_i, z_i)`` in
    ``(e1, e2, m)`` with ``|s r_1| = |s r_2| = s`` and ``r_1 . r_2 = 0`` give ``s^2`` as the
    larger root of ``S^2 - (|M_1|^2 + |M_2|^2) S + det(M)^2 = 0`` and ``(z_1, z_2)`` up to one
    common sign (the twins)."""
    centred = world - world.mean(axis=0)
    basis = np.linalg.svd(centred, full_matrices=False)[2]  # rows e1, e2, m (plane normal)
    uv = centred @ basis[:2].T
    design = np.concatenate([uv, np.ones((len(uv), 1))], axis=1)
    coef, *_ = np.linalg.lstsq(design, target, rcond=None)
    m = coef[:2].T  # [2, 2]: target = M (u, v) + t
    a1, a2, d12 = float(m[0] @ m[0]), float(m[1] @ m[1]), float(m[0] @ m[1])
    b = a1 + a2
    big = 0.5 * (b + np.sqrt(max(b * b - 4.0 * (a1 * a2 - d12 * d12), 0.0)))
    z1 = np.sqrt(max(big - a1, 0.0))
    z2 = np.sqrt(max(big - a2, 0.0)) * (-1.0 if d12 > 0 else 1.0)  # z1 z2 = -M_1 . M_2
    out = []
    for sign in (1.0, -1.0):
        rows = np.array([[*m[0], sign * z1], [*m[1], sign * z2]]) @ basis
        out.append(rows)
    return out


def fit_camera(world: np.ndarray, photo: np.ndarray) -> OrthoCamera:
    """The scaled orthographic camera that best projects ``world`` ``[N, 3]`` onto ``photo``
    ``[N, 2]`` (least squares, N >= 4 points not all on one line).

    Starts: the 3-D affine camera's nearest scaled rotation, and the two weak-perspective twins
    of the points' best plane (the only candidates when the points are nearly coplanar); each is
    refined by Levenberg-Marquardt on the reprojection error and the lowest wins."""
    xw = np.asarray(world, np.float64)
    xp = np.asarray(photo, np.float64)
    target = np.stack([xp[:, 0], -xp[:, 1]], axis=-1)  # (col, -row) = s (R X)_xy + (ox, -oy)
    design = np.concatenate([xw, np.ones((len(xw), 1))], axis=1)
    coef, *_ = np.linalg.lstsq(design, target, rcond=None)  # affine camera, [4, 2]
    candidates = [coef[:3].T] + _plane_candidates(xw, target)
    best = None
    for rows in candidates:  # three starts
        u, sv, vt = np.linalg.svd(rows, full_matrices=False)  # nearest scaled rotation
        r2 = u @ vt
        rot = np.vstack([r2, np.cross(r2[0], r2[1])])
        scale = max(float(sv.mean()), 1e-12)
        offset = (target - xw @ (scale * r2).T).mean(axis=0)
        start = np.concatenate(
            [Rotation.from_matrix(rot).as_rotvec(), [np.log(scale)], offset * [1.0, -1.0]]
        )
        fit = least_squares(_residuals, start, args=(xw, xp), method="lm")
        if best is None or fit.cost < best.cost * (1.0 - 1e-9) - 1e-18:
            best = fit
    assert best is not None
    res = best.fun.reshape(-1, 2)
    err = np.hypot(res[:, 0], res[:, 1])
    return OrthoCamera(
        rotation=Rotation.from_rotvec(best.x[:3]).as_matrix(),
        scale=float(np.exp(best.x[3])),
        offset=best.x[4:6].copy(),
        residual_px=float(np.sqrt(np.mean(err * err))),
        max_residual_px=float(err.max()),
    )


_VERT = """
#version 330
uniform mat3 rot;
uniform vec4 map;  // scale, offset col, offset row, unused
uniform vec2 size;  // photo width, height
uniform vec2 depth;  // camera-frame z of the nearest / farthest vertex
in vec3 pos;
in vec3 nrm;
out vec3 v_n;
void main() {
    vec3 c = rot * pos;
    float col = map.x * c.x + map.y;
    float row = -map.x * c.y + map.z;
    float z = (depth.x - c.z) / max(depth.x - depth.y, 1e-20);  // 0 nearest, 1 farthest
    gl_Position = vec4(2.0 * col / size.x - 1.0, 1.0 - 2.0 * row / size.y, 2.0 * z - 1.0, 1.0);
    v_n = rot * nrm;
}
"""

_FRAG = """
#version 330
in vec3 v_n;
out vec4 color;
void main() { color = vec4(normalize(v_n), 1.0); }
"""


def render_normals(
    mesh: Mesh, camera: OrthoCamera, shape: tuple[int, int], ctx: Any
) -> tuple[np.ndarray, np.ndarray]:
    """The mesh's camera-frame normals seen through ``camera`` at every photo pixel
    (``[H, W, 3]``, float32; nearest surface wins) and the pixels the mesh covers (``[H, W]``
    bool). Rendered with OpenGL into a 32-bit float target; ``ctx`` is a moderngl context
    (``wrinklepipe.validate.gl.create_context()``), which this releases nothing of but what it
    made."""
    h, w = shape
    pos = np.asarray(mesh.positions, np.float32)
    nrm = vertex_normals(mesh).astype(np.float32)
    zc = pos.astype(np.float64) @ camera.rotation[2]
    pad = 1e-3 * max(float(zc.max() - zc.min()), 1e-6)
    made = []
    try:
        prog = ctx.program(vertex_shader=_VERT, fragment_shader=_FRAG)
        made.append(prog)
        prog["rot"].write(camera.rotation.T.astype(np.float32).tobytes())  # column-major
        prog["map"].value = (camera.scale, float(camera.offset[0]), float(camera.offset[1]), 0.0)
        prog["size"].value = (float(w), float(h))
        prog["depth"].value = (float(zc.max() + pad), float(zc.min() - pad))
        vbo = ctx.buffer(np.concatenate([pos, nrm], axis=1).tobytes())
        ibo = ctx.buffer(np.asarray(mesh.indices, np.uint32).tobytes())
        vao = ctx.vertex_array(prog, [(vbo, "3f 3f", "pos", "nrm")], ibo)
        tex = ctx.texture((w, h), 4, dtype="f4")
        dep = ctx.depth_renderbuffer((w, h))
        fbo = ctx.framebuffer([tex], dep)
        made += [vbo, ibo, vao, tex, dep, fbo]
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        ctx.enable(ctx.DEPTH_TEST)
        vao.render()
        img = np.frombuffer(fbo.read(components=4, dtype="f4"), np.float32).reshape(h, w, 4)
    finally:
        for obj in reversed(made):
            obj.release()
    img = img[::-1]  # GL rows run bottom-up
    covered = img[..., 3] > 0.5
    n = np.where(covered[..., None], img[..., :3], np.array([0.0, 0.0, 1.0], np.float32))
    return np.ascontiguousarray(n, np.float32), covered
