"""Uncertainties of an adjustment that hold: variance components estimated from the data, and
the accuracy they predict at points that took no part in it.

Variance components (Förstner 1979; Koch, *Parameter estimation and hypothesis testing in
linear models*, 3.6): the observations fall into groups (the GCPs' columns, their rows, ...)
whose a-priori variances are known only up to one factor per group, ``sigma_i^2 = theta_g
q_i``. With the weights ``w_i = 1 / (theta_g q_i)`` and the least-squares residuals ``v``, each
group's share of the redundancy is ``r_g = n_g - tr(N^-1 N_g)`` (``N = A' W A``, ``N_g`` the same
sum over the group alone, so the ``r_g`` add up to ``n - u``), and the factor is updated by
``theta_g <- theta_g (v_g' W_g v_g) / r_g`` until every ratio is 1: the normalised residuals of
every group then have unit variance, and ``N^-1`` is the parameters' covariance with no further
``sigma0`` factor.

Prediction: a quantity ``y = f(p)`` of the parameters has the variance ``J C J'`` (``J`` its
partial derivatives, ``C`` the covariance); an image position at a ground point has that plus
the point's own measurement noise. GCPs taken from a reference DEM share its registration
error (a shift common to all, which the attitude biases absorb whole, so no residual shows
it): it moves every image position by ``G s`` (``G`` the partial derivatives of (col, row) by
the ground's east, north and up at the point, ``s`` the shift), a variance ``G S G'`` with
``S`` the reference's stated registration variances. An error of the model itself (a
lens, an attitude the corrections cannot follow) is as large at a check point as at the GCPs;
it is smooth across the image where GCP noise is not, so its variance is the covariance of
the residuals of neighbouring GCPs (the signal of least-squares collocation, Moritz), which
the prediction adds. But the GCPs' own ground errors (the reference's noise, the canopy share
it sees, overlapping surface-matching windows) are smooth over kilometres too: in a pair, only
the residuals' parallax, which no ground error makes, tells a model error
(:func:`parallax_covariance`); the rest is a correlated ground error
(:mod:`core.orientation.ground_field`), which a check point does not show itself but which does
not average out over the GCPs either, so it enters the parameters' covariance. The RMS
predicted over a set of points is the square root of the mean of those variances per axis.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import sparse

from core.errors import InputError

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class VarianceComponents:
    """The estimated factor ``theta`` of each observation group's a-priori variances (its
    ``sigma_scale`` is the square root: 1.4 means the a-priori sigmas were 1.4 times too
    small), with each group's number of observations ``n`` and share of the redundancy
    ``redundancy`` (the factor's relative sampling sigma is about ``sqrt(2 / redundancy)``).
    ``split``: the test that decided to keep groups apart (or to merge them), or ''."""

    names: tuple[str, ...]
    factors: FloatArray
    n: NDArray[np.intp]
    redundancy: FloatArray
    n_iterations: int
    converged: bool
    split: str = ""

    @property
    def sigma_scale(self) -> FloatArray:
        return np.sqrt(self.factors)

    def factor_of(self, name: str) -> float:
        return float(self.factors[self.names.index(name)])

    def to_dict(self) -> dict[str, Any]:
        return {"groups": {n: {"factor": float(f), "sigma_scale": float(np.sqrt(f)),
                               "n": int(k), "redundancy": float(r)}
                           for n, f, k, r in zip(self.names, self.factors, self.n,
                                                 self.redundancy, strict=True)},
                "n_iterations": self.n_iterations, "converged": self.converged,
                "split": self.split}


@dataclass(frozen=True, eq=False)
class ComponentSolution:
    """A weighted least-squares solution with its variance components: the correction ``dx``
    to the parameters, the residuals ``v`` (observed - computed after ``dx``), the covariance
    of ``dx`` (``N^-1`` under the estimated components) and the components."""

    dx: FloatArray
    v: FloatArray
    covariance: FloatArray
    components: VarianceComponents


SPARSE_MIN_PARAMS = 64  # a block's design: each row holds the parameters of 2-3 images
SPARSE_MAX_DENSITY = 0.25
LEVERAGE_ROWS = 8192  # rows of A N^-1 formed at a time (bounded memory)


def sparse_when_worth_it(a: FloatArray) -> FloatArray | sparse.csr_matrix:
    """``a`` as a CSR matrix when it has many columns and few of them non-zero in a row (a
    block of images: the normal equations then cost the rows' non-zeros, linear in the number
    of images, instead of rows x columns^2); else ``a`` itself."""
    if a.shape[1] < SPARSE_MIN_PARAMS:
        return a
    nnz = np.count_nonzero(a)
    return sparse.csr_matrix(a) if nnz <= SPARSE_MAX_DENSITY * a.size else a


def normal_matrix(a: FloatArray | sparse.csr_matrix, w: FloatArray) -> FloatArray:
    """``A' W A`` (dense (u, u))."""
    if sparse.issparse(a):
        return np.asarray((a.T @ a.multiply(w[:, None]).tocsr()).toarray())
    return a.T @ (a * w[:, None])


def _leverages(a: FloatArray | sparse.csr_matrix, n_inv: FloatArray) -> FloatArray:
    """``a_i N^-1 a_i'`` per row, ``LEVERAGE_ROWS`` rows at a time."""
    out = np.empty(a.shape[0])
    for i in range(0, a.shape[0], LEVERAGE_ROWS):
        rows = a[i:i + LEVERAGE_ROWS]
        if sparse.issparse(rows):
            out[i:i + LEVERAGE_ROWS] = np.asarray(rows.multiply(rows @ n_inv).sum(axis=1)).ravel()
        else:
            out[i:i + LEVERAGE_ROWS] = np.sum((rows @ n_inv) * rows, axis=1)
    return out


def solve_with_components(a: ArrayLike, r: ArrayLike, q: ArrayLike, groups: ArrayLike,
                          names: Sequence[str], factors: ArrayLike | None = None,
                          max_iterations: int = 50, tol: float = 1e-4,
                          fixed: Sequence[str] = ()) -> ComponentSolution:
    """Least squares ``a dx = r`` (``a`` (n, u), ``r`` (n,)) with the a-priori variances ``q``
    (n,) of the observations scaled per group (``groups`` (n,) indices into ``names``) by
    factors estimated from the residuals (Förstner's iteration, from ``factors`` or 1).

    A group with no redundancy of its own (``r_g`` under 0.5) keeps its starting factor, and
    so do the groups named in ``fixed`` (prior constraints: their sigma is a statement about the
    parameters, not a noise to estimate).
    """
    a = np.asarray(a, dtype=np.float64)
    r = np.asarray(r, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    g = np.asarray(groups, dtype=np.intp)
    n_groups = len(names)
    if a.ndim != 2 or r.shape != (a.shape[0],) or q.shape != r.shape or g.shape != r.shape:
        raise InputError(f"design {a.shape}, residuals {r.shape}, variances {q.shape} and "
                         f"groups {g.shape} do not agree")
    if not np.all(q > 0) or g.min(initial=0) < 0 or g.max(initial=0) >= n_groups:
        raise InputError("a-priori variances must be > 0 and groups index the names given")
    theta = (np.ones(n_groups) if factors is None
             else np.array(factors, dtype=np.float64).reshape(n_groups))
    scale = np.sqrt(np.sum(a**2 / q[:, None], axis=0))
    scale = np.where(scale > 0, scale, 1.0)
    a_s = a / scale  # columns of comparable size: the normal matrix stays well conditioned
    a_s = sparse_when_worth_it(a_s)
    n_obs = np.bincount(g, minlength=n_groups)
    red = np.zeros(n_groups)
    converged, it = False, 0
    for it in range(1, max_iterations + 1):
        w = 1.0 / (theta[g] * q)
        n_inv = np.linalg.pinv(normal_matrix(a_s, w), rcond=1e-12)
        dx_s = n_inv @ (a_s.T @ (w * r))
        v = r - a_s @ dx_s
        lev = w * _leverages(a_s, n_inv)  # w_i a_i N^-1 a_i'
        red = n_obs - np.bincount(g, weights=lev, minlength=n_groups)
        quad = np.bincount(g, weights=w * v**2, minlength=n_groups)
        ok = (red > 0.5) & ~np.isin(np.asarray(names), list(fixed))
        ratio = np.where(ok, quad / np.where(ok, red, 1.0), 1.0)
        theta = theta * ratio
        if np.max(np.abs(ratio - 1.0)) < tol:
            converged = True
            break
    w = 1.0 / (theta[g] * q)
    n_inv = np.linalg.pinv(normal_matrix(a_s, w), rcond=1e-12)
    dx_s = n_inv @ (a_s.T @ (w * r))
    comps = VarianceComponents(tuple(names), theta, n_obs, red, it, converged)
    return ComponentSolution(dx_s / scale, r - a_s @ dx_s, n_inv / np.outer(scale, scale), comps)


def components_differ(c: VarianceComponents, i: int, j: int, alpha: float = 0.01) -> bool:
    """Whether groups ``i`` and ``j`` have different factors: the two-sided F test of their
    ratio with their redundancies as degrees of freedom, at level ``alpha``."""
    from scipy.stats import f

    d1, d2 = float(c.redundancy[i]), float(c.redundancy[j])
    if d1 < 1 or d2 < 1:
        return False
    ratio = float(c.factors[i] / c.factors[j])
    p = 2.0 * min(f.cdf(ratio, d1, d2), f.sf(ratio, d1, d2))
    return bool(p < alpha)


def predicted_variances(jac: ArrayLike, covariance: ArrayLike) -> FloatArray:
    """``J C J'`` per point and axis: ``jac`` (n, 2, u) partial derivatives of (col, row) by
    the ``u`` parameters, ``covariance`` (u, u); returns (n, 2) variances (px^2)."""
    j = np.asarray(jac, dtype=np.float64)
    c = np.asarray(covariance, dtype=np.float64)
    if j.ndim != 3 or c.shape != (j.shape[2], j.shape[2]):
        raise InputError(f"Jacobian {j.shape} and covariance {c.shape} do not agree")
    return np.clip(np.sum((j @ c) * j, axis=2), 0.0, None)


def ground_jacobian(model: Any, lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike,
                    step_m: float = 1.0) -> FloatArray:
    """d(col, row)/d(east, north, up) of ``model`` (a SensorModel) at ground points: (n, 2, 3),
    pixels per metre, by central differences of ``step_m``."""
    from core.geodesy import metres_per_degree

    lon = np.atleast_1d(np.asarray(lon_deg, dtype=np.float64))
    lat = np.atleast_1d(np.asarray(lat_deg, dtype=np.float64))
    h = np.atleast_1d(np.asarray(h_m, dtype=np.float64))
    m_lon, m_lat = metres_per_degree(lat)
    out = np.empty((lon.size, 2, 3))
    moves = ((step_m / m_lon, 0.0, 0.0), (0.0, step_m / m_lat, 0.0), (0.0, 0.0, step_m))
    for k, (dl, dp, dh) in enumerate(moves):
        c1, r1 = model.project(lon + dl, lat + dp, h + dh)
        c0, r0 = model.project(lon - dl, lat - dp, h - dh)
        out[:, 0, k] = (np.asarray(c1) - c0) / (2.0 * step_m)
        out[:, 1, k] = (np.asarray(r1) - r0) / (2.0 * step_m)
    return out


def predicted_rms_px(jac: ArrayLike, covariance: ArrayLike,
                     sigma_px: ArrayLike = 0.0) -> tuple[float, float]:
    """Predicted RMS (col, row) in pixels of the differences between the adjusted model's
    projections and measurements of the points: the parameters' error propagated to each point
    (:func:`predicted_variances`) plus each measurement's own noise ``sigma_px`` (a scalar,
    (n,) or (n, 2)), averaged over the points. The same with ``jac`` from
    :func:`ground_jacobian` and ``covariance`` the reference's registration variances gives
    that term."""
    var = predicted_variances(jac, covariance)
    s = np.broadcast_to(np.asarray(sigma_px, dtype=np.float64).reshape(
        (-1, 1) if np.ndim(sigma_px) == 1 else np.shape(sigma_px)), var.shape)
    if var.shape[0] == 0:
        return float("nan"), float("nan")
    m = np.mean(var + s**2, axis=0)
    return float(np.sqrt(m[0])), float(np.sqrt(m[1]))


@dataclass(frozen=True)
class PredictedAccuracy:
    """Predicted check-point RMS (px) in one image, col and row, over ``n`` points: in total
    (``predicted_rms_*``) and its terms, the adjustment's covariance given the control's frames
    (``adjustment_rms_*``), the frames' registration (``reference_rms_*``: the reference's,
    ``reference_sigma_m`` east, north, up, and any other frame's, carried through the models),
    the model's own error the GCP residuals show (``unmodelled_rms_*``,
    :func:`neighbour_covariance`) and the points' own measurement noise ``noise_px``:
    ``predicted^2 = adjustment^2 + reference^2 + unmodelled^2 + noise^2``. What the method
    achieves relative to the frames (``predicted_relative_rms_*``: all but the reference term)
    and what the frames carry (``predicted_reference_rms_*``, the reference term) are the two
    parts of the total."""

    n: int
    predicted_rms_col_px: float
    predicted_rms_row_px: float
    adjustment_rms_col_px: float
    adjustment_rms_row_px: float
    reference_rms_col_px: float
    reference_rms_row_px: float
    unmodelled_rms_col_px: float
    unmodelled_rms_row_px: float
    reference_sigma_m: tuple[float, float, float]
    noise_px: float

    @property
    def predicted_relative_rms_col_px(self) -> float:
        return float(np.sqrt(self.adjustment_rms_col_px**2 + self.unmodelled_rms_col_px**2
                             + self.noise_px**2))

    @property
    def predicted_relative_rms_row_px(self) -> float:
        return float(np.sqrt(self.adjustment_rms_row_px**2 + self.unmodelled_rms_row_px**2
                             + self.noise_px**2))

    @property
    def predicted_reference_rms_col_px(self) -> float:
        return self.reference_rms_col_px

    @property
    def predicted_reference_rms_row_px(self) -> float:
        return self.reference_rms_row_px

    @classmethod
    def split(cls, param_jac: ArrayLike, relative_covariance: ArrayLike,
              reference_covariance: ArrayLike, reference_sigma_m: tuple[float, float, float],
              unmodelled_px: tuple[float, float] = (0.0, 0.0), noise_px: float = 0.0
              ) -> PredictedAccuracy:
        """The terms at points with partial derivatives ``param_jac`` (n, 2, u) by the
        parameters, whose covariance is the sum of ``relative_covariance`` (what remains were
        the frames known) and ``reference_covariance`` (what the frames' uncertainty puts
        there; ``reference_sigma_m``: the reference's prior, for the record)."""
        ac, ar = predicted_rms_px(param_jac, relative_covariance)
        rc, rr = predicted_rms_px(param_jac, reference_covariance)
        uc, ur = (float(x) for x in unmodelled_px)
        s = tuple(float(v) for v in reference_sigma_m)
        return cls(int(np.shape(param_jac)[0]),
                   float(np.sqrt(ac**2 + rc**2 + uc**2 + noise_px**2)),
                   float(np.sqrt(ar**2 + rr**2 + ur**2 + noise_px**2)), ac, ar, rc, rr, uc, ur,
                   (s[0], s[1], s[2]), float(noise_px))

    @classmethod
    def at(cls, param_jac: ArrayLike, covariance: ArrayLike, ground_jac: ArrayLike,
           reference_sigma_m: tuple[float, float, float],
           unmodelled_px: tuple[float, float] = (0.0, 0.0), noise_px: float = 0.0
           ) -> PredictedAccuracy:
        """The terms at points with partial derivatives ``param_jac`` (n, 2, u) by the
        parameters and ``ground_jac`` (n, 2, 3) by the ground (:func:`ground_jacobian`);
        ``unmodelled_px``: the model's own error (col, row; px RMS)."""
        ac, ar = predicted_rms_px(param_jac, covariance)
        s = np.asarray(reference_sigma_m, dtype=np.float64)
        if s.shape != (3,) or np.any(s < 0):
            raise InputError(f"reference_sigma_m is (east, north, up) >= 0 m, got "
                             f"{reference_sigma_m}")
        rc, rr = predicted_rms_px(ground_jac, np.diag(s**2))
        uc, ur = (float(x) for x in unmodelled_px)
        return cls(int(np.shape(param_jac)[0]),
                   float(np.sqrt(ac**2 + rc**2 + uc**2 + noise_px**2)),
                   float(np.sqrt(ar**2 + rr**2 + ur**2 + noise_px**2)), ac, ar, rc, rr, uc, ur,
                   (float(s[0]), float(s[1]), float(s[2])), float(noise_px))

    def to_dict(self) -> dict[str, Any]:
        d = dict(vars(self))
        d["reference_sigma_m"] = list(self.reference_sigma_m)
        for k in ("predicted_relative_rms_col_px", "predicted_relative_rms_row_px",
                  "predicted_reference_rms_col_px", "predicted_reference_rms_row_px"):
            d[k] = getattr(self, k)
        return d


def neighbour_covariance(col: ArrayLike, row: ArrayLike, v: ArrayLike,
                         t_min: float = 2.0) -> float:
    """The covariance of residuals ``v`` at image points (``col``, ``row``) with those of
    their nearest neighbours, ``mean(v_i v_nn(i))`` (px^2): the variance of the part of ``v``
    smooth across the image, a model error; independent noise averages out of it. 0 unless it
    exceeds ``t_min`` times its standard error (independent noise alone would otherwise leave
    a spurious term of about 0.4 sigma with 40 points), and with fewer than 3 points."""
    from scipy.spatial import cKDTree

    pts = np.column_stack([np.asarray(col, dtype=np.float64), np.asarray(row, dtype=np.float64)])
    v = np.asarray(v, dtype=np.float64)
    if v.size < 3:
        return 0.0
    _, j = cKDTree(pts).query(pts, k=2)
    pairs = np.unique(np.sort(np.column_stack([np.arange(v.size), j[:, 1]]), axis=1), axis=0)
    prod = v[pairs[:, 0]] * v[pairs[:, 1]]  # each pair once (mutual neighbours are one pair)
    m, se = float(np.mean(prod)), float(np.std(prod) / np.sqrt(prod.size))
    return m if m > t_min * se else 0.0


def parallax_covariance(ground_jac: ArrayLike, v: ArrayLike, col: ArrayLike, row: ArrayLike,
                        t_min: float = 2.0) -> float:
    """The model's own error per pixel axis (px^2) that the residuals ``v`` (n, m, 2) of
    points seen in ``m >= 2`` images show and an error of the points' ground cannot:
    :func:`neighbour_covariance` of each point's residuals projected out of the span of its
    ground Jacobian ``ground_jac`` (n, m, 2, 3, :func:`ground_jacobian`), i.e. of the
    parallax, the ``2 m - 3`` directions no east/north/up move of the point makes.

    A GCP taken from a reference DEM carries the reference's error there (its noise, the
    canopy share it sees, a tilt), correlated over kilometres, so over the GCPs' spacing: in
    their residuals it is as smooth as a model error, and :func:`neighbour_covariance` of
    the raw residuals counts it as one, though a check point (exact ground) never shows it.
    Its image signature is ``G e``, which the projection removes whole; what is left of a
    smooth model error ``d`` is ``Q d`` (``Q = I - G G^+``), whose expectation at neighbours
    ``i``, ``j`` is ``tr(Q_i Q_j)`` times the per-axis variance when the model error is alike
    in every image axis (the only statement the GCPs allow about the directions they cannot
    see). Returned: ``mean((Q_i v_i)'(Q_j v_j)) / mean(tr(Q_i Q_j))`` over the nearest-
    neighbour pairs (in (``col``, ``row``) of one image), 0 unless above ``t_min`` standard
    errors (independent noise averages out of it), and with fewer than 3 points."""
    return _neighbour_parallax(ground_jac, v, np.column_stack(
        [np.asarray(col, dtype=np.float64), np.asarray(row, dtype=np.float64)]), t_min)


def _neighbour_parallax(ground_jac: ArrayLike, v: ArrayLike, pts: ArrayLike,
                        t_min: float) -> float:
    """:func:`parallax_covariance` over the nearest-neighbour pairs in the coordinates ``pts``
    (n, k)."""
    from scipy.spatial import cKDTree

    g = np.asarray(ground_jac, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    n = v.shape[0]
    if g.ndim != 4 or g.shape[1:] != (v.shape[1], 2, 3) or v.shape[2:] != (2,) \
            or v.shape[1] < 2:
        raise InputError(f"ground Jacobian {g.shape} and residuals {v.shape} must be "
                         "(n, m, 2, 3) and (n, m, 2) with m >= 2 images")
    if n < 3:
        return 0.0
    gf = g.reshape(n, -1, 3)
    q = np.eye(gf.shape[1]) - gf @ np.linalg.pinv(gf)  # (n, 2m, 2m) onto the parallax
    w = np.einsum("nij,nj->ni", q, v.reshape(n, -1))
    pts = np.asarray(pts, dtype=np.float64).reshape(n, -1)
    _, j = cKDTree(pts).query(pts, k=2)
    pairs = np.unique(np.sort(np.column_stack([np.arange(n), j[:, 1]]), axis=1), axis=0)
    a, b = pairs[:, 0], pairs[:, 1]
    prod = np.einsum("ni,ni->n", w[a], w[b])
    tr = np.einsum("nij,nji->n", q[a], q[b])
    m = float(np.sum(prod) / np.sum(tr))
    se = float(np.std(prod) / np.sqrt(prod.size) / np.mean(tr))
    return m if m > t_min * se else 0.0


def along_track_covariance(ground_jac: ArrayLike, v: ArrayLike, row: ArrayLike,
                           t_min: float = 2.0) -> float:
    """The model's own error per pixel axis (px^2) that follows the time of imaging: the
    covariance of the parallax (as :func:`parallax_covariance`) at points nearest in time in
    every image. An attitude error is the same for every detector of a line, so points a few
    lines apart share it wherever they are across the image, while their matching
    noise is independent: jitter faster than the GCPs' spacing, which the 2-D neighbours of
    :func:`parallax_covariance` see as noise, shows here when the points are dense in time
    (the tie points: hundreds per image).

    ``row`` is (n,) or (n, m): each point's row in each image. The parallax holds every
    image's error, each at its own time; two points share all of it only when they are near
    in time in every image, so the neighbours are sought in the m-D space of rows. Two images
    turned against each other (two orbits, two dates: the same ground line 250 rows apart at
    the two ends of a 6000-column spot line) put points of one left row at right rows far
    apart, so neighbours in one image's row alone share only that image's error: half the
    variance of the two images' jitter."""
    r = np.asarray(row, dtype=np.float64)
    return _neighbour_parallax(ground_jac, v, r.reshape(r.shape[0], -1), t_min)


def image_grid(n_cols: int, n_rows: int, n_side: int = 9) -> tuple[FloatArray, FloatArray]:
    """A regular ``n_side`` x ``n_side`` grid of pixel centres spanning the image (first to
    last pixel), as flat (col, row) arrays."""
    if n_cols < 1 or n_rows < 1 or n_side < 2:
        raise InputError(f"an image of {n_cols}x{n_rows} px and a grid of {n_side} per side "
                         "(need >= 1 px and >= 2 points per side)")
    c, r = np.meshgrid(np.linspace(0.0, n_cols - 1.0, n_side),
                       np.linspace(0.0, n_rows - 1.0, n_side))
    return c.ravel(), r.ravel()
