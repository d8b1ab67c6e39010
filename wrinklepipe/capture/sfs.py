"""Shape from shading: the crease height whose Lambertian ratio image matches R.

Under a light at the camera a Lambertian pixel is ``I = C N_z``, so with the neutral surface's
normal ``n0`` known the ratio image is, for a crease height ``c`` (pixels, along the view axis,
added to the neutral height ``h0``)::

    R_model = e N1_z / N0_z,   N1_z = 1 / sqrt(1 + |g0 + grad c|^2),   g0 = grad h0

(``e`` the exposure ratio of the two flashes). The method solves for ``c`` over the ROI with
``c = 0`` outside it (the crease meets the neutral face at the ROI border)::

    min_c  sum_ROI (R_model - R)^2  +  smooth sum |grad c|^2

by Levenberg-Marquardt (Gauss-Newton) steps, each a sparse symmetric system solved by conjugate
gradients preconditioned with algebraic multigrid (pyamg). The slope field is integrable by
construction (it is the gradient of ``c``), the border condition ties every crease to the
neutral, and where the neutral is tilted (``N0_z < 1``) the ratio depends on the *sign* of the
crease's slope to first order (``R ~ 1 - g0 . grad c``): ridges and valleys are told apart by
the data, not by a prior. Where the neutral faces the camera (``g0 = 0``) ``c`` and ``-c`` fit
equally (the concave/convex ambiguity): several starts are solved (zero, the ``integrable``
prior and its mirror) and the lowest residual wins; a tie (within the noise) keeps the prior's
sign (creases are dents).

The result's normals, relative to the neutral surface, are the smallest rotation taking ``n0``
to +Z applied to the expression's normal ``(-(g0 + grad c), 1)``; its tilt from the camera is
set back to the measured one (``N1_z = R N0_z / e``) so the data's detail is not smoothed by
the solve. The residual (RMS of ``R_model - R`` over the ROI, also in units of the ratio's noise)
is reported: a residual near the noise means the height explains the photos.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage, sparse
from scipy.sparse import linalg as spla
from threadpoolctl import threadpool_limits

from wrinklepipe.capture.grid import (
    _Blur,
    _blur_on_grid,
    _downsample,
    _extend,
    _Grid,
    _grid,
    _integrate,
    _multigrid,
    _to_full,
    _up_nearest,
)
from wrinklepipe.capture.heights import eikonal_height, neutral_height
from wrinklepipe.capture.slopes import expression_normals, neutral_slopes


@dataclass(frozen=True)
class SfsOptions:
    """Parameters of the shape-from-shading solve."""

    #: Weight of the smoothness term ``|grad c|^2`` relative to the data (R units squared).
    smooth: float = 2e-4
    #: Weight of ``c^2`` (pixels^2): creases are local, the face's broad shape is the neutral's.
    shrink: float = 2e-6
    #: Gauss-Newton (Levenberg-Marquardt) steps per start (fewer when it has converged).
    iterations: int = 8
    #: Photos larger than this (pixels per side) are solved on an integer-downsampled grid and
    #: the solution's orientation is carried back to every pixel.
    max_side: int = 320
    #: Gaussian window (pixels of the solve grid) over which the starts' local residuals are
    #: compared when they are fused into one more start.
    fuse_sigma: float = 6.0
    #: Conjugate-gradient tolerance of each step (relative residual).
    cg_tol: float = 1e-3
    #: CG iterations per step (measured: 10, 25 and 60 give the same solutions to the reported
    #: digits; 10 costs ~30 % less CPU).
    cg_maxiter: int = 10
    #: Estimate the exposure ratio jointly with the height (else R is taken as normalised).
    fit_exposure: bool = True
    #: The first start (the prior) is kept unless another ends with a residual lower by more
    #: than this fraction (measured: on a nearly flat neutral whose creases are all dents the
    #: eikonal start ends 7 % below the prior while orienting at chance; where the data carry
    #: the sign it ends 30-70 % below).
    tie: float = 0.1
    #: Gaussian blur (pixels, for a photo up to 256 px wide: times the sigma scale) of the R the
    #: solve fits and takes its tilt from; it includes the ratio's own ``--blur``. Measured on
    #: the 256 px curved sessions against 1.0: the targets met go from 3/2/5 to 3/3/6 (angular /
    #: tilt / orientation, of 7); 1.4 is better on mixed creases, worse on the foreheads.
    blur: float = 1.2
    #: Start from the viscosity solutions of the eikonal equation ``|grad h| = |p|`` (the
    #: expression's slope magnitude from R) with the neutral's height on the ROI border
    #: (:func:`eikonal_height`, both kinds), when the neutral is turned from the camera.
    eikonal: bool = True
    #: Coarse to fine: the whole solve (every start) first runs on a grid this many times
    #: twice as coarse, and each coarser result is one more start on the next finer grid
    #: (a crease's sign is settled at the coarse scale, where the search has fewer local minima).
    coarse: int = 1
    #: Solutions whose residual is within this fraction of the winner's count as explaining
    #: the photos as well; where one of them leans the other way the sign is reported ambiguous
    #: (measured, 10 starts: 80 % of the crease pixels on the nearly flat mixed session whose
    #: sign the photos do not carry, 1-16 % on the others).
    ambiguity: float = 0.2
    #: Polish the winner: a last refinement whose model ratio is blurred as R was (R is
    #: blurred, an unblurred model fitted to it pulls narrow creases' slopes towards the
    #: neutral's: the exact truth's ratio is 0.0053 RMS from R on the N_z 0.8 forehead,
    #: 0.0018 blurred alike), with ``polish_curvature`` ``|laplacian c|^2`` against what the
    #: blur hides (without it the polish fits noise: mixed N_z 0.8 tilt 0.30x -> 0.33x). The
    #: search (starts, fusion, choice) fits the plain model, whose minima were measured more
    #: reliable for the sign.
    polish: bool = True
    #: Weight of ``|laplacian c|^2`` (pixels^-2, relative to the data) in the polish. Measured
    #: (256 px sessions, default): 1e-3 gives 5 of 8 cases all three targets; 1e-2 is worse in
    #: tilt on the forehead (0.27x -> 0.31x).
    polish_curvature: float = 1e-3
    #: No coarser level below this many pixels on the short side (a crease 2-5 px wide at
    #: 192 px is lost on a 96 px grid: measured on the example session, the coarse start won
    #: there with a lower residual and oriented worse, 7.7 degrees against the prior's 3.4).
    coarse_min_side: int = 128
    #: One more start on every grid: the best solution so far minus its broad part (its
    #: Gaussian blur with this sigma, grid pixels). A crease whose flank leans the wrong way
    #: lifts the height beyond it (a broad step the search cannot take back: measured on the
    #: 512 px forehead, a drift of 2 px over the crease's 0.6 px); without it the solve can
    #: reach the right flanks. Measured (8 sessions): the 512 px forehead 0.67x / 0.21x / 79.5 %
    #: -> 0.56x / 0.18x / 82.8 %, forehead 0.9 0.39x / 0.26x / 93 % -> 0.37x / 0.25x / 94 %, the
    #: others unchanged within 0.003; 4 and 16 px measured alike. 0 turns it off. Only on a
    #: neutral turned from the camera: on one facing it the detrended height's mirror would
    #: explain R as well but is not a start, so the sign ambiguity would go unreported.
    detrend: float = 8.0
    #: Weight of the side-lit photo's misfit relative to the ratio image's (both ratios of
    #: photos with similar noise).
    side_weight: float = 1.0
    #: The crease height at the ROI border: ``"zero"`` (the crease meets the neutral there) or
    #: ``"free"`` (natural border: creases may run through the ROI's edge).
    border: str = "zero"


@dataclass
class SfsResult:
    """The crease height, its slopes and how well it explains R."""

    height: np.ndarray  # [H, W] crease height c (pixels), 0 outside the ROI
    slopes: np.ndarray  # [H, W, 2] expression slopes p = g0 + grad c, pixel frame (col, row)
    exposure: float  # the exposure factor fitted (1 when not fitted)
    residual: float  # RMS of R_model - R over the ROI (R units)
    starts: dict[str, float]  # residual of every start, by name
    start: str  # the winning start
    factor: int  # downsampling factor of the solve grid
    #: [H, W] bool: crease pixels of the winner where another solution that explains R nearly
    #: as well (``SfsOptions.ambiguity``) leans the other way: the photos do not fix the sign
    ambiguous: np.ndarray | None = None
    #: share of the winner's crease pixels (crease slope above tan 3 degrees) that are ambiguous
    ambiguous_fraction: float = 0.0


# --- the grid operators ------------------------------------------------------------------------


# --- the solve ---------------------------------------------------------------------------------


def _model(p_x: np.ndarray, p_y: np.ndarray, inv_nz0: np.ndarray) -> tuple[np.ndarray, ...]:
    """Model ratio ``N1_z / N0_z`` and its derivatives with respect to the slopes."""
    n1 = 1.0 / np.sqrt(1.0 + p_x * p_x + p_y * p_y)
    rho = n1 * inv_nz0
    d = -(n1**3) * inv_nz0  # d rho / d p = -N1_z^3 p / N0_z
    return rho, d * p_x, d * p_y


@dataclass(frozen=True)
class _Side:
    """The side-lit photo's data on the unknowns: ``S = l_z - l_x p_col + l_y p_row`` (the
    side-lit over the flash-lit expression, ``n1 . l / N1_z``: linear in the slopes ``p``)."""

    ax: np.ndarray  # -l_x (per unknown)
    ay: np.ndarray  # +l_y
    base: np.ndarray  # the model at the neutral's slopes: l_z + ax g0x + ay g0y
    target: np.ndarray  # the measured S (exposure normalised)
    weight: float  # relative to the ratio image's term

    def model(self, qx: np.ndarray, qy: np.ndarray, blur: _Blur | None) -> np.ndarray:
        lin = self.ax * qx + self.ay * qy  # the crease's part (0 outside the unknowns)
        return self.base + (blur(lin) if blur is not None else lin)


def _solve(
    grid: _Grid,
    g0x: np.ndarray,
    g0y: np.ndarray,
    inv_nz0: np.ndarray,
    ratio: np.ndarray,
    weight: np.ndarray,
    blur: _Blur | None,
    c0: np.ndarray,
    exposure: float,
    o: SfsOptions,
    curvature: float = 0.0,
    side: _Side | None = None,
) -> tuple[np.ndarray, float, float]:
    """Levenberg-Marquardt on the unknown heights; returns (c, exposure, weighted RMS). With
    ``blur`` the model ratio is blurred as R was (the Gauss-Newton systems are then solved
    matrix-free, preconditioned by the unblurred system's multigrid). ``side``: the side-lit
    photo's term too (its RMS joins the residual, weighted)."""
    c = c0.copy()
    lam = o.smooth
    lap = (grid.reg.T @ grid.reg).tocsr()
    reg_t_reg = (lap + (o.shrink / max(lam, 1e-30)) * sparse.identity(len(c))).tocsr()
    if curvature > 0:  # |laplacian c|^2 on top
        reg_t_reg = (reg_t_reg + (curvature / max(lam, 1e-30)) * (lap.T @ lap)).tocsr()
    wsum = max(float(weight.sum()), 1e-12)
    dxt, dyt = grid.dx.T.tocsr(), grid.dy.T.tocsr()

    def energy(cc: np.ndarray, e: float) -> tuple[float, tuple[np.ndarray, ...]]:
        px = g0x + grid.dx @ cc
        py = g0y + grid.dy @ cc
        rho, drx, dry = _model(px, py, inv_nz0)
        if blur is not None:
            rho = blur.ratio(rho)
        f = e * rho - ratio
        total = float(weight @ (f * f) + lam * (cc @ (reg_t_reg @ cc)))
        fs = None
        if side is not None:
            fs = side.model(px - g0x, py - g0y, blur) - side.target
            total += side.weight * float(weight @ (fs * fs))
        return total, (px, py, rho, drx, dry, f, fs)

    e = exposure
    energy_now, st = energy(c, e)
    mu = 1e-2
    diag_w = sparse.diags(weight)
    if side is not None:  # the side term's Jacobian is constant (linear in the slopes)
        jac_s = (sparse.diags(side.ax) @ grid.dx + sparse.diags(side.ay) @ grid.dy).tocsr()
        jtj_s = side.weight * (jac_s.T @ diag_w @ jac_s)
    for _ in range(o.iterations):  # ten Gauss-Newton steps, each one sparse solve
        px, py, rho, drx, dry, f, fs = st
        jac = (sparse.diags(e * drx) @ grid.dx + sparse.diags(e * dry) @ grid.dy).tocsr()
        jtj = jac.T @ diag_w @ jac + lam * reg_t_reg
        if side is not None:
            jtj = jtj + jtj_s
        jtj = jtj.tocsr()
        scale = float(jtj.diagonal().mean()) or 1.0
        a = (jtj + sparse.identity(jtj.shape[0]) * (mu * scale)).tocsr()
        # a fresh preconditioner per step: reusing the first step's was measured 2x slower
        # (more CG iterations than the set-up it saves)
        precond = _multigrid(a)
        if blur is None:
            b = -(jac.T @ (weight * f) + lam * (reg_t_reg @ c))
            if side is not None:
                b = b - side.weight * (jac_s.T @ (weight * fs))
            op: spla.LinearOperator | sparse.csr_matrix = a
        else:
            jx, jy = e * drx, e * dry

            def jt(y: np.ndarray, jx: np.ndarray = jx, jy: np.ndarray = jy) -> np.ndarray:
                t = blur(y)
                return dxt @ (jx * t) + dyt @ (jy * t)

            def normal(
                v: np.ndarray, jx: np.ndarray = jx, jy: np.ndarray = jy, damp: float = mu * scale
            ) -> np.ndarray:
                jv = blur(jx * (grid.dx @ v) + jy * (grid.dy @ v))
                out = jt(weight * jv) + lam * (reg_t_reg @ v) + damp * v
                if side is not None:
                    out = out + side.weight * (jac_s.T @ blur(weight * blur(jac_s @ v)))
                return out

            b = -(jt(weight * f) + lam * (reg_t_reg @ c))
            if side is not None:
                b = b - side.weight * (jac_s.T @ blur(weight * fs))
            op = spla.LinearOperator(a.shape, matvec=normal, dtype=np.float64)
        step, _ = spla.cg(op, b, rtol=o.cg_tol, maxiter=o.cg_maxiter, M=precond)

        trial = c + step
        e_trial = e
        if o.fit_exposure:
            _, (_, _, rho_t, *_rest) = energy(trial, e)
            num = float(weight @ (rho_t * ratio))
            den = float(weight @ (rho_t * rho_t))
            if den > 0:
                e_trial = float(np.clip(num / den, 0.8 * exposure, 1.25 * exposure))
        energy_trial, st_trial = energy(trial, e_trial)
        if energy_trial < energy_now:
            done = energy_now - energy_trial < 1e-4 * energy_now
            c, e, energy_now, st = trial, e_trial, energy_trial, st_trial
            mu = max(mu / 3.0, 1e-6)
            if done:
                break
        else:
            mu *= 10.0
    f, fs = st[5], st[6]
    sq = float(weight @ (f * f))
    if fs is not None:
        sq += side.weight * float(weight @ (fs * fs))  # type: ignore[union-attr]
    return c, e, float(np.sqrt(sq / wsum))


def solve_crease(
    ratio: np.ndarray,
    n0: np.ndarray,
    roi: np.ndarray,
    valid: np.ndarray | None = None,
    starts: dict[str, np.ndarray] | None = None,
    options: SfsOptions | None = None,
    blur: float = 0.0,
    side: tuple[np.ndarray, np.ndarray] | None = None,
) -> SfsResult:
    """Solve for the crease height of every start; keep the one with the lowest residual.

    ``ratio`` is R (exposure roughly normalised, unclipped), ``n0`` the neutral's camera-frame
    normals ``[H, W, 3]``, ``roi`` (0..1) the region (c = 0 outside), ``valid`` the pixels that
    were divided. ``starts`` maps names to initial slope fields ``[H, W, 2]`` (pixel frame, of
    the crease alone) in preference order (the first wins ties, see ``SfsOptions.tie``); when
    the neutral is tilted the zero start and the two eikonal starts are tried too, and with
    ``SfsOptions.coarse`` the whole solve first runs on a grid half as fine, its result one
    more start (coarse to fine). ``blur``: the Gaussian sigma (photo pixels) R was blurred
    with; the model ratio is blurred alike (fitting an unblurred model to a blurred R pulls
    the creases' slopes towards the neutral's: measured on the N_z 0.8 forehead, the exact
    truth's ratio is 0.0053 RMS from the blurred R, blurred alike 0.0018).
    ``side``: ``(S, l)``, a photo of the expression lit from the unit direction ``l`` (camera
    frame) over the flash-lit expression photo, registered and blurred as R, exposure
    normalised (``S = n1 . l / N1_z``, linear in the slopes: the crease's sign in every pixel);
    its misfit joins the objective with weight ``SfsOptions.side_weight``.
    """
    o = options or SfsOptions()
    h, w = np.shape(ratio)
    k = max(1, int(np.ceil(max(h, w) / o.max_side)))
    return _solve_on_grid(ratio, n0, roi, valid, starts or {}, o, k, o.coarse, blur, side=side)


def _solve_on_grid(
    ratio: np.ndarray,
    n0: np.ndarray,
    roi: np.ndarray,
    valid: np.ndarray | None,
    starts: dict[str, np.ndarray],
    o: SfsOptions,
    k: int,
    levels: int,
    blur: float = 0.0,
    polish: bool = True,
    side: tuple[np.ndarray, np.ndarray] | None = None,
) -> SfsResult:
    """:func:`solve_crease` on the grid downsampled by ``k``, after ``levels`` coarser solves
    (each on a grid twice as coarse; the coarser result is a start here)."""
    r_full = np.asarray(ratio, np.float64)
    h, w = r_full.shape
    coarse = None
    if levels > 0 and min(h, w) // (2 * k) >= o.coarse_min_side:
        coarse = _solve_on_grid(
            ratio, n0, roi, valid, starts, o, 2 * k, levels - 1, blur, False, side
        )
    in_roi = np.asarray(roi, np.float64) > 0.5
    ok = in_roi if valid is None else in_roi & np.asarray(valid, bool)
    rr = _downsample(r_full, k)
    nn = _downsample(np.asarray(n0, np.float64), k)
    nn = nn / np.linalg.norm(nn, axis=-1, keepdims=True)
    mask = _downsample(in_roi.astype(np.float64), k) > 0.5
    wgt = _downsample(ok.astype(np.float64), k)
    grid = _grid(mask, o.border == "free")
    u = grid.unknown
    g0 = neutral_slopes(nn)
    g0x, g0y = g0[..., 0].ravel()[u], g0[..., 1].ravel()[u]
    inv_nz0 = 1.0 / np.maximum(nn[..., 2].ravel()[u], 1e-3)
    rv = rr.ravel()[u]
    wv = np.where(wgt.ravel()[u] > 0.5, 1.0, 0.0)
    sd = None
    if side is not None:
        light = np.asarray(side[1], np.float64)
        ax, ay = np.full(len(u), -light[0]), np.full(len(u), light[1])
        sd = _Side(
            ax,
            ay,
            light[2] + ax * g0x + ay * g0y,
            _downsample(np.asarray(side[0], np.float64), k).ravel()[u],
            o.side_weight,
        )
    tried: dict[str, tuple[np.ndarray, float, float]] = {}
    inits: dict[str, np.ndarray] = {}
    # the search (every start, the fusion, the choice) fits the plain model; the winner is then
    # polished with R's blur in the model (``SfsOptions.polish``)
    blur_op = _blur_on_grid(blur, k, grid) if blur > 0 else None
    args = (g0x, g0y, inv_nz0, rv, wv, blur_op if not o.polish else None)
    tilted = np.abs(g0[mask]).max() > 1e-3 if mask.any() else False
    tilted = tilted or sd is not None  # a side light shows the sign even on a flat neutral
    more = dict(starts)
    if coarse is not None:  # the coarser grid's solution, crease slopes at full resolution
        more["coarse"] = coarse.slopes - neutral_slopes(n0)
    with threadpool_limits(1):  # sparse, memory-bound work: BLAS threads only contend
        for name, q in more.items():  # a few starts
            # slopes are dimensionless: the same on the coarse grid (heights in its pixels)
            qs = _downsample(np.asarray(q, np.float64), k)
            inits[name] = _integrate(grid, qs[..., 0].ravel()[u], qs[..., 1].ravel()[u])
        if tilted:  # from the neutral itself (a saddle where it is flat)
            inits["zero"] = np.zeros(len(u))
        if o.eikonal and tilted:
            # the expression's slope magnitude |g0 + grad c| from R (exposure ~ normalised)
            n1z = np.clip(rr * nn[..., 2], 1e-3, 1.0)
            slope = np.sqrt(1.0 / (n1z * n1z) - 1.0)
            h0 = neutral_height(mask, g0)
            for name, up in (("eikonal", True), ("eikonal_down", False)):
                inits[name] = (eikonal_height(slope, mask, h0, up) - h0).ravel()[u]
        for name, c0 in inits.items():
            tried[name] = _solve(grid, *args, c0, 1.0, o, side=sd)
        if len(tried) > 1:
            fused = _fuse(grid, {n: v[0] for n, v in tried.items()}, args, mask.shape, o, sd)
            tried["fused"] = _solve(grid, *args, fused, 1.0, o, side=sd)
        if o.detrend > 0 and tilted:  # the best so far without its broad part, solved again
            lead = min(tried, key=lambda n: tried[n][2])
            c_lead = tried[lead][0]
            c_flat = c_lead - _Blur(grid.shape, u, o.detrend)(c_lead)
            tried["detrended"] = _solve(grid, *args, c_flat, 1.0, o, side=sd)
    best = min(tried, key=lambda n: tried[n][2])
    first = next(iter(tried))
    if tried[first][2] <= tried[best][2] * (1.0 + o.tie):
        best = first  # a tie keeps the preferred start (the prior's sign)
    c_small, exposure, resid = tried[best]
    if o.polish and blur_op is not None and polish:
        with threadpool_limits(1):
            c_small, exposure, resid = _solve(
                grid, *args[:5], blur_op, c_small, exposure, o, o.polish_curvature, sd
            )
    amb_small, amb_fraction = _ambiguity(grid, tried, best, o.ambiguity)
    amb = np.zeros(mask.shape, bool)
    amb.ravel()[u] = amb_small
    c = _to_full(c_small, u, mask.shape, k, (h, w), in_roi, grid.free)
    d_row, d_col = np.gradient(_extend(c, in_roi) if grid.free else c)
    p = neutral_slopes(n0) + np.stack([d_col, d_row], axis=-1)
    return SfsResult(
        height=c,
        slopes=p,
        exposure=exposure,
        residual=resid,
        starts={n: v[2] for n, v in tried.items()},
        start=best,
        factor=k,
        ambiguous=_up_nearest(amb, k, (h, w)) & in_roi,
        ambiguous_fraction=amb_fraction,
    )


#: A crease pixel of a solution: its crease slope exceeds tan(3 degrees) (the evaluation's
#: crease threshold).
CREASE_SLOPE = float(np.tan(np.radians(3.0)))


def _ambiguity(
    grid: _Grid, tried: dict[str, tuple[np.ndarray, float, float]], best: str, window: float
) -> tuple[np.ndarray, float]:
    """Crease pixels of the winner where another solution whose residual is within ``window``
    (relative) of the winner's leans the opposite way, and their share of the winner's crease
    pixels. Two heights that explain R equally well but disagree on a crease's sign are the
    concave/convex ambiguity made visible: the photos do not decide there."""
    cb = tried[best][0]
    qb = np.stack([grid.dx @ cb, grid.dy @ cb], axis=-1)
    crease = np.hypot(qb[:, 0], qb[:, 1]) > CREASE_SLOPE
    amb = np.zeros(len(cb), bool)
    limit = tried[best][2] * (1.0 + window)
    for name, (c, _, resid) in tried.items():  # a few solutions
        if name != best and resid <= limit:
            q = np.stack([grid.dx @ c, grid.dy @ c], axis=-1)
            amb |= np.einsum("ic,ic->i", q, qb) < 0
    amb &= crease
    return amb, float(amb.sum() / max(int(crease.sum()), 1))


def _fuse(
    grid: _Grid,
    solutions: dict[str, np.ndarray],
    args: tuple[np.ndarray, ...],
    shape: tuple[int, int],
    o: SfsOptions,
    side: _Side | None = None,
) -> np.ndarray:
    """One more start: at every pixel the slopes of the solution whose residual is lowest
    nearby (Gaussian window), integrated (a fusion move: each crease from the start that
    explains it best)."""
    g0x, g0y, inv_nz0, rv, wv, blur = args
    local = []
    slopes = []
    for c in solutions.values():  # a few solutions
        qx, qy = grid.dx @ c, grid.dy @ c
        rho, *_ = _model(g0x + qx, g0y + qy, inv_nz0)
        if blur is not None:
            rho = blur.ratio(rho)
        f = np.zeros(shape[0] * shape[1])
        f[grid.unknown] = wv * (rho - rv) ** 2
        if side is not None:
            f[grid.unknown] += side.weight * wv * (side.model(qx, qy, blur) - side.target) ** 2
        local.append(ndimage.gaussian_filter(f.reshape(shape), o.fuse_sigma).ravel()[grid.unknown])
        slopes.append((qx, qy))
    pick = np.argmin(np.stack(local), axis=0)
    qx = np.choose(pick, [q[0] for q in slopes])
    qy = np.choose(pick, [q[1] for q in slopes])
    return _integrate(grid, qx, qy)


def ratio_residual(
    normals: np.ndarray,
    n0: np.ndarray,
    ratio: np.ndarray,
    roi: np.ndarray,
    valid: np.ndarray | None = None,
    exposure: float = 1.0,
    max_side: int = SfsOptions.max_side,
    blur: float = 0.0,
) -> float:
    """How well a wrinkle normal map explains the photos: its slopes are integrated into a
    height (least squares, zero outside the ROI), the height's Lambertian ratio image is
    rendered and compared with R: RMS over the ROI (R units). Comparable across methods: a map
    that is not integrable, or leans the wrong way, cannot reproduce R once integrated.
    ``blur``: R's Gaussian blur (photo pixels), applied to the rendered ratio alike."""
    r = np.asarray(ratio, np.float64)
    h, w = r.shape
    k = max(1, int(np.ceil(max(h, w) / max_side)))
    in_roi = np.asarray(roi, np.float64) > 0.5
    ok = in_roi if valid is None else in_roi & np.asarray(valid, bool)
    nn = _downsample(np.asarray(n0, np.float64), k)
    nn = nn / np.linalg.norm(nn, axis=-1, keepdims=True)
    mm = _downsample(np.asarray(normals, np.float64), k)
    mask = _downsample(in_roi.astype(np.float64), k) > 0.5
    wv = (_downsample(ok.astype(np.float64), k) > 0.5).ravel()
    grid = _grid(mask)
    u = grid.unknown
    if len(u) == 0:
        return 0.0
    n1 = expression_normals(mm, nn)
    z = np.maximum(n1[..., 2], 1e-3)
    q = np.stack([-n1[..., 0] / z, n1[..., 1] / z], axis=-1) - neutral_slopes(nn)
    with threadpool_limits(1):
        c = _integrate(grid, q[..., 0].ravel()[u], q[..., 1].ravel()[u])
    g0 = neutral_slopes(nn)
    rho, *_ = _model(
        g0[..., 0].ravel()[u] + grid.dx @ c,
        g0[..., 1].ravel()[u] + grid.dy @ c,
        1.0 / np.maximum(nn[..., 2].ravel()[u], 1e-3),
    )
    op = _blur_on_grid(blur, k, grid) if blur > 0 else None
    if op is not None:
        rho = op.ratio(rho)
    f = (exposure * rho - _downsample(r, k).ravel()[u])[wv[u]]
    return float(np.sqrt(np.mean(f * f))) if f.size else 0.0
