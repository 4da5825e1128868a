"""Relief sufficiency: whether a scene gives SRTM surface matching what it needs, and if not
the true reason, in one line with its figures (too small for a window, reference voids, too
few windows, too flat).

:func:`scene_size_verdict` judges the pair's overlap before anything is matched;
:func:`relief_sufficiency` judges the windows :func:`core.matching.surface.match_window`
matched or refused, each by the precision its relief promises with the noise its correlation
reveals (:func:`realistic_precision_m`). No I/O here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from core.matching.surface import SurfaceMatchConfig, WindowMatch, WindowStatus


@dataclass(frozen=True)
class ReliefVerdict:
    """Whether the scene gives surface matching what it needs, judged before orienting, and
    if not the true reason (:attr:`reason`).

    ``n_qualified``: windows whose relief promises ``max_precision_m`` (the precision predicted
    from the relief and the measured noise, see :func:`realistic_precision_m`), of
    ``n_windows`` placed; ``n_small``: windows the relative DEM fills with fewer than
    ``min_cells`` lattice cells of ``cell_m`` (the scene, or its overlap, is smaller than a
    window: ``best_dem_cells`` is the most any window got); ``n_voids``: windows the relative
    DEM fills but the reference leaves without heights (voids) or that are masked beyond the
    allowed share; the other windows are judged on their relief. ``relief_found_m``: the
    median relief (std of heights) of the judged windows; ``relief_needed_m``: the median over
    them of the relief that would have made them qualify (the predicted precision goes as one
    over the slopes, so as one over the relief of a terrain of the same shape; NaN when no
    judged window has a slope).
    """

    n_windows: int
    n_qualified: int
    n_needed: int
    relief_found_m: float
    relief_needed_m: float
    max_precision_m: float
    n_small: int = 0
    n_voids: int = 0
    best_dem_cells: int = 0
    min_cells: int = 100
    cell_m: float = float("nan")
    radius_m: float = float("nan")

    @property
    def enough(self) -> bool:
        return self.n_qualified >= self.n_needed

    @property
    def n_judged(self) -> int:
        return self.n_windows - self.n_small - self.n_voids

    @property
    def reason(self) -> str | None:
        """None when enough windows qualify, else why not: ``"too_small"`` (no window holds
        enough of the relative DEM: the scene is smaller than a window), ``"voids"`` (the
        reference has no heights under the windows), ``"few_windows"`` (too few windows fit in
        the scene: every one judged qualifies, or fewer are judged than needed, so that no
        relief would have been enough), ``"too_flat"``."""
        if self.enough:
            return None
        if self.n_judged == 0:
            return "too_small" if self.n_small >= self.n_voids else "voids"
        if self.n_qualified == self.n_judged or self.n_judged < self.n_needed:
            return "few_windows"
        return "too_flat"

    def message(self) -> str:
        """The refusal in one line: what was found, what is needed, what to do. Never NaN."""
        n, need = self.n_windows, self.n_needed
        skipped = "" if not (self.n_small or self.n_voids) else (
            f" ({self.n_small} too little of the scene, {self.n_voids} on reference voids)")
        if self.reason == "too_small":
            area = self.min_cells * self.cell_m**2 / 1e6
            have = self.best_dem_cells * self.cell_m**2 / 1e6
            return (f"the scene is too small for SRTM surface matching: the best of {n} windows "
                    f"holds {self.best_dem_cells} cells of the relative DEM at the reference's "
                    f"{self.cell_m:.0f} m (about {have:.2g} km2), {self.min_cells} are needed "
                    f"(about {area:.2g} km2 of overlap, in windows of radius "
                    f"{self.radius_m:g} m); use a scene covering kilometres of terrain, or "
                    "real GCPs")
        if self.reason == "voids":
            return (f"the reference DEM has no heights under the scene: {self.n_voids} of {n} "
                    f"surface-matching windows fall on its voids or are masked beyond the "
                    f"allowed share; fill the reference's voids (gcpfree fill-voids) or use "
                    "another reference")
        if self.reason == "few_windows":
            return (f"the scene holds too few surface-matching windows: {n} placed, "
                    f"{self.n_qualified} with enough relief{skipped}, {need} needed; use a "
                    "larger scene, or lower --min-windows or --window-radius")
        if np.isfinite(self.relief_needed_m):
            needed = f"needed about {self.relief_needed_m:.1f} m"
        else:
            needed = "no window has a slope to match on"
        return (f"the terrain is too flat for GCP-free orientation: {self.n_qualified} of "
                f"{self.n_judged} windows judged{skipped} have the relief to fix the position "
                f"to {self.max_precision_m:g} m ({need} needed); relief found "
                f"{self.relief_found_m:.1f} m (median std of heights per window), {needed}; "
                "use real GCPs or a scene with more relief")

    def to_dict(self) -> dict[str, Any]:
        return {k: (None if isinstance(v, float) and not np.isfinite(v) else v)
                for k, v in vars(self).items()} | {"enough": self.enough,
                                                    "reason": self.reason}


def scene_size_verdict(overlap_m2: float, cfg: SurfaceMatchConfig,
                       cell_m: float) -> str | None:
    """Before anything is matched: None when the pair's overlap (``overlap_m2``, its largest
    over the heights the scene may have) can hold one surface-matching window's
    ``cfg.min_cells`` lattice cells of ``cell_m`` (the reference's cell, or ``cfg.cell_m``),
    else the refusal, with its figures. The relief verdict judges the windows afterwards; this
    only spares minutes of matching on a scene that cannot hold one window."""
    cell = float(cfg.cell_m if cfg.cell_m is not None else cell_m)
    needed = cfg.min_cells * cell**2
    if not overlap_m2 < needed:
        return None
    return (f"the scene is too small for SRTM surface matching: the two images overlap on about "
            f"{overlap_m2 / 1e6:.2g} km2 ({overlap_m2 / cell**2:.0f} cells of the reference's "
            f"{cell:.0f} m), one window needs {cfg.min_cells} cells (about "
            f"{needed / 1e6:.2g} km2); use a scene covering kilometres of terrain, or real GCPs")


def realistic_precision_m(m: WindowMatch, cfg: SurfaceMatchConfig) -> float:
    """The precision a window's relief promises with the noise its correlation reveals, when
    that exceeds the reference's nominal noise (``cfg.height_noise_m``).

    A surface of relief ``r`` (std) seen through independent noise ``n`` correlates with the
    noise-free one at ``rho = r^2 / (r^2 + n^2)``, so the peak correlation measures the noise
    between the two surfaces, ``n = r sqrt(1 / rho - 1)``: the relative DEM's own noise, canopy,
    the reference's errors. On terrain of a few tens of metres of relief that noise, not SRTM's,
    decides (simulated tiny at 40 m pixels, relief scaled by 0.05: windows promising 10 m with
    the nominal noise, none of them correlating). A window refused before matching keeps the
    nominal prediction.
    """
    rho = m.correlation
    if not (np.isfinite(rho) and 0.0 < rho < 1.0 and np.isfinite(m.relief_m)):
        return m.predicted_precision_m
    noise = m.relief_m * float(np.sqrt(1.0 / rho - 1.0))
    return m.predicted_precision_m * max(noise / cfg.height_noise_m, 1.0)


def relief_sufficiency(matches: Sequence[WindowMatch], cfg: SurfaceMatchConfig,
                       n_needed: int, cell_m: float | None = None) -> ReliefVerdict:
    """The verdict on ``matches`` (windows matched or refused by
    :func:`core.matching.surface.match_window`), each
    judged by :func:`realistic_precision_m`; ``cell_m`` the lattice cell the windows were
    averaged on (``cfg.cell_m`` or the reference's), for the message."""
    def filled(m: WindowMatch) -> int:  # n_cells (with a reference height) <= n_dem_cells;
        return max(m.n_dem_cells, m.n_cells)  # windows.json of older runs lack the latter

    small = [m for m in matches if filled(m) < cfg.min_cells]
    voids = [m for m in matches if filled(m) >= cfg.min_cells
             and m.status in (WindowStatus.TOO_FEW_CELLS, WindowStatus.MASKED)]
    sized = [m for m in matches if filled(m) >= cfg.min_cells
             and m.status not in (WindowStatus.TOO_FEW_CELLS, WindowStatus.MASKED)
             and np.isfinite(m.relief_m)]
    precision = [realistic_precision_m(m, cfg) for m in sized]
    qualified = [m for m, p in zip(sized, precision, strict=True) if p <= cfg.max_precision_m]
    found = float(np.median([m.relief_m for m in sized])) if sized else 0.0
    need = [m.relief_m * p / cfg.max_precision_m for m, p in zip(sized, precision, strict=True)
            if np.isfinite(p) and m.relief_m > 0]
    needed = float(np.median(need)) if need else float("nan")
    return ReliefVerdict(
        len(matches), len(qualified), n_needed, found, needed, cfg.max_precision_m,
        n_small=len(small), n_voids=len(voids),
        best_dem_cells=max((filled(m) for m in matches), default=0),
        min_cells=cfg.min_cells,
        cell_m=float(cfg.cell_m if cfg.cell_m is not None else
                     (cell_m if cell_m is not None else float("nan"))),
        radius_m=cfg.radius_m)
