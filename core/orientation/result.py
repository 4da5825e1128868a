"""The result of the absolute orientation (:func:`core.orientation.absolute.
absolute_orientation`): the adjusted models, the covariance of every image's and frame's
parameters, the residuals at the GCPs, and the predictions they make at points that took no
part in the adjustment (:meth:`AbsoluteOrientation.predict`): relative to the control's frames
and what the frames' registrations carry.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.orientation.equations import frame_design
from core.orientation.frames import (
    REFERENCE,
    FrameEstimate,
    FrameLayout,
    FramePrior,
    frame_estimates,
)
from core.orientation.observations import Observations
from core.orientation.uncertainty import (
    PredictedAccuracy,
    VarianceComponents,
    ground_jacobian,
    image_grid,
)
from core.sensors.base import SensorModel

FloatArray = NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class ImageResiduals:
    """Residuals (measured - projected, px) of one image at the GCPs kept: ``rms_col_px`` is the
    paper's P, ``rms_row_px`` its L; ``unmodelled_*_px`` the part of them smooth across the
    image, the model's own error (:func:`core.orientation.uncertainty.neighbour_covariance`,
    square-rooted)."""

    name: str
    n: int
    rms_col_px: float
    rms_row_px: float
    mean_col_px: float
    mean_row_px: float
    col_px: FloatArray = field(repr=False)
    row_px: FloatArray = field(repr=False)
    unmodelled_col_px: float = 0.0
    unmodelled_row_px: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "n": self.n, "rms_col_px": self.rms_col_px,
                "rms_row_px": self.rms_row_px, "mean_col_px": self.mean_col_px,
                "mean_row_px": self.mean_row_px}


@dataclass(frozen=True, eq=False)
class AbsoluteOrientation:
    """The adjusted models and how well they fit the GCPs.

    ``rejected`` lists the GCP indices removed, with the normalised residual that condemned
    each (``reasons``); ``covariance`` is over the concatenated parameters of all images (in
    each model's parameter units) followed by the frames' (m; ``frame_layout``), under the GCP
    sigmas calibrated on the data (``components``; without them, the a-priori sigmas times
    ``sigma0``); ``sigma0`` the robust a-posteriori standard deviation of unit weight under
    the a-priori sigmas; ``frame_params`` the frames' estimated parameters.
    """

    models: tuple[SensorModel, ...]
    names: tuple[str, ...]
    param_names: tuple[tuple[str, ...], ...]
    params_before: tuple[FloatArray, ...]
    params_after: tuple[FloatArray, ...]
    covariance: FloatArray
    sigma0: float
    residuals: tuple[ImageResiduals, ...]
    inlier: NDArray[np.bool_]
    reasons: dict[int, str]
    n_iterations: int
    converged: bool
    components: VarianceComponents | None = None
    n_ties: int = 0
    tie_rms_px: float | None = None
    frame_layout: FrameLayout = field(
        default_factory=lambda: FrameLayout.of((FramePrior(REFERENCE, (0.0, 0.0, 0.0)),)))
    frame_params: FloatArray = field(default_factory=lambda: np.zeros(0))

    @property
    def rejected(self) -> NDArray[np.intp]:
        return np.flatnonzero(~self.inlier)

    @property
    def n_model_params(self) -> int:
        return sum(len(p) for p in self.param_names)

    def _image_slice(self, k: int) -> slice:
        start = sum(len(p) for p in self.param_names[:k])
        return slice(start, start + len(self.param_names[k]))

    def image_covariance(self, k: int) -> FloatArray:
        """The covariance of image ``k``'s parameters (its block of ``covariance``)."""
        s = self._image_slice(k)
        return self.covariance[s, s]

    def frame_covariance(self) -> FloatArray:
        s = slice(self.n_model_params, self.covariance.shape[0])
        return self.covariance[s, s]

    def frames(self) -> tuple[FrameEstimate, ...]:
        """Each frame's prior, estimated shift and posterior sigma."""
        return frame_estimates(self.frame_layout, self.frame_params, self.frame_covariance())

    def split_covariance(self, k: int) -> tuple[FloatArray, FloatArray]:
        """Image ``k``'s parameter covariance split into what remains were the frames known
        (the relative part: ``C_kk - C_kf C_ff^-1 C_fk``) and what the frames' uncertainty
        puts there (the reference part: ``C_kf C_ff^-1 C_fk``); they add up to its block."""
        s = self._image_slice(k)
        f = slice(self.n_model_params, self.covariance.shape[0])
        c_kk = self.covariance[s, s]
        if f.stop == f.start:
            return c_kk, np.zeros_like(c_kk)
        c_kf, c_ff = self.covariance[s, f], self.covariance[f, f]
        ref = c_kf @ np.linalg.pinv(c_ff, rcond=1e-12, hermitian=True) @ c_kf.T
        ref = 0.5 * (ref + ref.T)
        return c_kk - ref, ref

    def predict(self, k: int, lon_deg: ArrayLike, lat_deg: ArrayLike, h_m: ArrayLike,
                noise_px: float = 0.0) -> PredictedAccuracy:
        """Predicted RMS (col, row; px) of check points at these ground points in image ``k``:
        the parameters' covariance propagated through the model's partial derivatives there
        (its relative part and the part the frames' registrations put there,
        :meth:`split_covariance`), the model's own error the GCP residuals show (their part
        smooth across the image) and the check points' own measurement noise ``noise_px``."""
        model, res = self.models[k], self.residuals[k]
        rel, ref = self.split_covariance(k)
        reference = self.frame_layout.priors[0].sigma_m if self.frame_layout.priors \
            else (0.0, 0.0, 0.0)
        return PredictedAccuracy.split(model.jacobian(lon_deg, lat_deg, h_m), rel, ref,
                                       reference,
                                       (res.unmodelled_col_px, res.unmodelled_row_px),
                                       noise_px)

    def predict_over_image(self, k: int, size: tuple[int, int], heights_m: ArrayLike,
                           n_side: int = 9) -> PredictedAccuracy:
        """:meth:`predict` over a regular ``n_side`` x ``n_side`` grid of image ``k``'s pixels
        (``size``: cols, rows) at each of ``heights_m``: what error-free check points spread
        evenly over the image at those heights would show."""
        c, r = image_grid(size[0], size[1], n_side)
        model = self.models[k]
        lon, lat, h = [], [], []
        for hk in np.asarray(heights_m, dtype=np.float64).ravel():
            lo, la = model.localize(c, r, np.full(c.shape, hk))
            lon.append(lo)
            lat.append(la)
            h.append(np.full(c.shape, hk))
        return self.predict(k, np.concatenate(lon), np.concatenate(lat), np.concatenate(h))

    def gcp_design(self, obs: Observations, use: NDArray[np.bool_]
                   ) -> tuple[FloatArray, FloatArray]:
        """At the GCPs ``obs`` (their ground as given: the frames' shifts are added here) and
        the measurements ``use`` (n, m) taken: the partial derivatives of every measurement
        by every parameter (n, m, 2, u; models' and frames'; zero where not measured) and by
        the ground (n, m, 2, 3; px per m)."""
        o = obs.shifted(self.frame_layout, self.frame_params)
        n, m = np.shape(o.col)
        u = self.covariance.shape[0]
        jac = np.zeros((n, m, 2, u))
        ground = np.zeros((n, m, 2, 3))
        start = 0
        for k, model in enumerate(self.models):
            stop = start + len(self.param_names[k])
            sel = use[:, k]
            if sel.any():
                jac[sel, k, :, start:stop] = model.jacobian(o.lon_deg[sel], o.lat_deg[sel],
                                                            o.h_m[sel])
                ground[sel, k] = ground_jacobian(model, o.lon_deg[sel], o.lat_deg[sel],
                                                 o.h_m[sel])
            start = stop
        if self.frame_layout.n:
            only = np.zeros_like(use)
            for k in range(m):
                only[:, k] = use[:, k]
                rows = frame_design(self.models, o, only, self.frame_layout)
                jac[use[:, k], k, :, start:] = rows.reshape(-1, 2, self.frame_layout.n)
                only[:, k] = False
        return jac, ground

    def sigmas(self) -> tuple[FloatArray, ...]:
        """Standard deviation of each image's parameters."""
        sd = np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))
        out, k = [], 0
        for names in self.param_names:
            out.append(sd[k:k + len(names)])
            k += len(names)
        return tuple(out)

    def to_dict(self) -> dict[str, Any]:
        return {
            "images": {
                n: {"param_names": list(pn), "params_before": pb.tolist(),
                    "params_after": pa.tolist(), "sigmas": s.tolist(), **r.to_dict()}
                for n, pn, pb, pa, s, r in zip(self.names, self.param_names, self.params_before,
                                               self.params_after, self.sigmas(), self.residuals,
                                               strict=True)},
            "sigma0": self.sigma0, "n_gcps": int(self.inlier.sum()),
            "rejected": [{"index": int(i), "reason": self.reasons[int(i)]}
                         for i in self.rejected],
            "n_iterations": self.n_iterations, "converged": self.converged,
            "tie_points": ({"n": self.n_ties, "rms_px": self.tie_rms_px} if self.n_ties
                           else None),
            "variance_components": (self.components.to_dict() if self.components is not None
                                    else None),
            "frames": [f.to_dict() for f in self.frames()],
        }
