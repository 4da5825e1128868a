"""The figures of the run report (matplotlib, Agg canvas, PNG bytes): what Goncalves and Toutin
show. Each function takes arrays already read and computed by :mod:`tasks.report.build` and only
draws them; no pyplot, so no global state and no display is needed.
"""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from matplotlib.figure import Figure

STATUS_COLOURS = {"OK": "#2a9d2a", "LOW_RELIEF": "#e69f00", "LOW_CORRELATION": "#cc79a7",
                  "IMPRECISE": "#d55e00", "EDGE_PEAK": "#9467bd", "MASKED": "#7f7f7f",
                  "TOO_FEW_CELLS": "#bbbbbb"}
DPI = 110
# windows the relief verdict leaves out (too few cells to judge their relief)
UNCOUNTED = ("MASKED", "TOO_FEW_CELLS")


def png_bytes(fig: Figure) -> bytes:
    """The figure as PNG bytes (Agg)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, bbox_inches="tight")
    return buf.getvalue()


def _colour(status: str) -> str:
    return STATUS_COLOURS.get(status, "#1f77b4")


def _image_axes(ax, size: tuple[int, int], image: np.ndarray | None = None) -> None:
    """Axes in full-resolution pixel coordinates (col right, row down), the (decimated) image
    stretched over them."""
    w, h = size
    if image is not None:
        finite = image[np.isfinite(image)]
        lo, hi = (np.percentile(finite, (2, 98)) if finite.size else (0.0, 1.0))
        ax.imshow(image, cmap="gray", vmin=lo, vmax=hi if hi > lo else lo + 1,
                  extent=(-0.5, w - 0.5, h - 0.5, -0.5), interpolation="bilinear")
    ax.set_xlim(-0.5, w - 0.5)
    ax.set_ylim(h - 0.5, -0.5)
    ax.set_aspect("equal")
    ax.set_xlabel("column P (px)")
    ax.set_ylabel("row L (px)")


@dataclass(frozen=True, eq=False)
class Points:
    """Image positions (px) of a set of points drawn with one style."""

    col: np.ndarray
    row: np.ndarray
    label: str


def tie_points_figure(image: np.ndarray | None, size: tuple[int, int],
                      inliers: Points, outliers: Points | None,
                      windows: Sequence[tuple[Points, str]], gcps_used: Points | None,
                      gcps_rejected: Points | None) -> Figure:
    """Tie points over the left image, the surface-matching window centres coloured by status
    and the GCPs kept or rejected."""
    fig = Figure(figsize=(8.5, 8.5 * size[1] / max(size[0], 1) * 0.9 + 0.5))
    ax = fig.add_subplot()
    _image_axes(ax, size, image)
    ax.plot(inliers.col, inliers.row, "+", color="#00b4ff", ms=6, mew=1.2, label=inliers.label)
    if outliers is not None and outliers.col.size:
        ax.plot(outliers.col, outliers.row, "x", color="red", ms=6, label=outliers.label)
    for pts, status in windows:
        ax.plot(pts.col, pts.row, "s", mfc="none", mec=_colour(status), ms=11, mew=1.5,
                label=pts.label)
    if gcps_used is not None and gcps_used.col.size:
        ax.plot(gcps_used.col, gcps_used.row, "o", color="#2a9d2a", ms=4, label=gcps_used.label)
    if gcps_rejected is not None and gcps_rejected.col.size:
        ax.plot(gcps_rejected.col, gcps_rejected.row, "X", color="red", ms=9,
                label=gcps_rejected.label)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=3, fontsize=8)
    ax.set_title("Tie points and surface-matching windows on the left image")
    return fig


def correlation_figure(shifts_arcsec: np.ndarray, rho: np.ndarray,
                       peak_arcsec: tuple[float, float], title: str) -> Figure:
    """Goncalves's Fig. 5: the correlation over the (dlon, dlat) shift grid of one window, as a
    surface and as a map with the refined peak."""
    fig = Figure(figsize=(12, 5))
    gx, gy = np.meshgrid(shifts_arcsec, shifts_arcsec)
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    z = np.where(np.isfinite(rho), rho, np.nan)
    ax3.plot_surface(gx, gy, z, cmap="viridis", linewidth=0, antialiased=True,
                     vmin=np.nanmin(z), vmax=np.nanmax(z))
    ax3.set_xlabel('dlon (")')
    ax3.set_ylabel('dlat (")')
    ax3.set_zlabel("correlation")
    ax = fig.add_subplot(1, 2, 2)
    half = 0.5 * (shifts_arcsec[1] - shifts_arcsec[0]) if shifts_arcsec.size > 1 else 0.5
    im = ax.imshow(z, origin="lower", cmap="viridis",
                   extent=(shifts_arcsec[0] - half, shifts_arcsec[-1] + half,
                           shifts_arcsec[0] - half, shifts_arcsec[-1] + half))
    ax.contour(gx, gy, z, levels=10, colors="white", linewidths=0.5, alpha=0.6)
    ax.plot(*peak_arcsec, "r+", ms=14, mew=2, label=f'peak ({peak_arcsec[0]:.2f}", '
            f'{peak_arcsec[1]:.2f}")')
    ax.set_xlabel('dlon (")')
    ax.set_ylabel('dlat (")')
    ax.legend(loc="upper right", fontsize=8)
    fig.colorbar(im, ax=ax, label="correlation coefficient")
    fig.suptitle(title)
    return fig


@dataclass(frozen=True, eq=False)
class Profile:
    """One line of the profile figure: distance along the profile (km) and heights (m)."""

    dist_km: np.ndarray
    h_m: np.ndarray
    label: str
    style: str = "-"


def profile_figure(lines: Sequence[Profile], title: str) -> Figure:
    """Goncalves's Fig. 4: the relative DEM against the reference along a profile (and the
    relative DEM moved by a window's 3-D shift, the final DSM when there is one)."""
    fig = Figure(figsize=(11, 4.5))
    ax = fig.add_subplot()
    for line in lines:
        ax.plot(line.dist_km, line.h_m, line.style, lw=1.2, label=line.label)
    ax.set_xlabel("distance east from the DEM's west edge (km)")
    ax.set_ylabel("ellipsoidal height (m)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title)
    return fig


def row_profile_figure(before: Mapping[str, Any], after: Mapping[str, Any],
                       title: str) -> Figure:
    """The GCPs' row residuals averaged in bands of image rows, per image, without and with the
    along-track attitude (``absolute.along_track.row_profile_without`` / ``_with``): an
    unmodelled attitude profile shows as a wave."""
    fig = Figure(figsize=(11, 4.0))
    names = list(before)
    for k, name in enumerate(names):
        ax = fig.add_subplot(1, len(names), k + 1)
        for prof, style, label in ((before[name], "o--", "without"),
                                   (after.get(name, {}), "s-", "with")):
            rows = np.asarray(prof.get("row_centres", []), dtype=float)
            v = np.array([np.nan if x is None else x
                          for x in prof.get("mean_row_residual_px", [])], dtype=float)
            if rows.size:
                ax.plot(rows, v, style, lw=1.2, label=f"{label} along-track attitude")
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_xlabel(f"{name} image row")
        ax.set_ylabel("mean GCP row residual (px)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper right")
    fig.suptitle(title)
    return fig


def relief_figure(relief_m: np.ndarray, predicted_m: np.ndarray, statuses: Sequence[str],
                  max_precision_m: float, verdict: str) -> Figure:
    """The relief-sufficiency verdict: each window's relief against the precision its relief
    promises, the threshold, windows coloured by outcome."""
    fig = Figure(figsize=(8, 5))
    ax = fig.add_subplot()
    st = np.asarray(statuses)
    for s in dict.fromkeys(statuses):
        k = st == s
        uncounted = s in UNCOUNTED
        ax.scatter(relief_m[k], predicted_m[k], s=28, linewidth=0.8 if uncounted else 0.3,
                   facecolor="none" if uncounted else _colour(s),
                   edgecolor=_colour(s) if uncounted else "k",
                   label=f"{s} ({int(k.sum())}){', not counted' if uncounted else ''}")
    ax.axhline(max_precision_m, color="red", ls="--", lw=1,
               label=f"precision needed {max_precision_m:g} m")
    positive = np.concatenate([relief_m[relief_m > 0], predicted_m[predicted_m > 0]])
    if positive.size:
        ax.set_xscale("log")
        ax.set_yscale("log")
    ax.set_xlabel("window relief: std of heights about their plane or quadratic (m)")
    ax.set_ylabel("precision predicted from the relief (m)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=8)
    ax.set_title(verdict, fontsize=10)
    return fig


@dataclass(frozen=True, eq=False)
class Residuals:
    """Residual vectors (measured - projected, px) of points in one image; ``flagged`` marks
    the rejected ones."""

    name: str
    size: tuple[int, int]
    col: np.ndarray
    row: np.ndarray
    d_col: np.ndarray
    d_row: np.ndarray
    flagged: np.ndarray


def residual_vectors_figure(panels: Sequence[Residuals], title: str,
                            flagged_label: str = "rejected") -> Figure:
    """Residual vectors in each image, magnified to be seen (the key gives the scale); flagged
    points in red."""
    fig = Figure(figsize=(6.2 * len(panels), 6.4))
    allv = np.concatenate([np.hypot(p.d_col, p.d_row)[~p.flagged] for p in panels]
                          or [np.ones(1)])  # flagged vectors may be longer than the scale
    allv = allv[np.isfinite(allv)]
    vmax = float(np.max(allv)) if allv.size and np.max(allv) > 0 else 1.0
    key = float(10 ** np.floor(np.log10(vmax)))
    for i, p in enumerate(panels, start=1):
        ax = fig.add_subplot(1, len(panels), i)
        _image_axes(ax, p.size)
        mag = 0.1 * max(p.size) / vmax  # the longest vector kept: 10 % of the image
        ok = ~p.flagged
        if ok.any():
            q = ax.quiver(p.col[ok], p.row[ok], p.d_col[ok], p.d_row[ok], angles="xy",
                          scale_units="xy", scale=1.0 / mag, color="#1f4e9c", width=0.004)
            ax.quiverkey(q, 0.2, 1.03, key, f"{key:g} px", labelpos="E", coordinates="axes")
        if p.flagged.any():
            ax.quiver(p.col[~ok], p.row[~ok], p.d_col[~ok], p.d_row[~ok], angles="xy",
                      scale_units="xy", scale=1.0 / mag, color="red", width=0.004)
            ax.plot(p.col[~ok], p.row[~ok], "x", color="red", ms=7,
                    label=f"{flagged_label} ({int(p.flagged.sum())})")
            ax.legend(loc="lower right", fontsize=8)
        ax.plot(p.col[ok], p.row[ok], ".", color="#1f4e9c", ms=3)
        ax.set_title(f"{p.name}: {int(ok.sum())} points"
                     + (f", {int(p.flagged.sum())} {flagged_label}" if p.flagged.any() else ""),
                     pad=18)
    fig.suptitle(title)
    return fig


def histogram_figure(groups: Sequence[tuple[str, np.ndarray, np.ndarray]], title: str) -> Figure:
    """Histograms of residuals per group (title, column residuals, row residuals), px."""
    n = max(len(groups), 1)
    ncol = min(n, 2)
    nrow = int(np.ceil(n / ncol))
    fig = Figure(figsize=(6 * ncol, 3.6 * nrow))
    for i, (name, dc, dr) in enumerate(groups, start=1):
        ax = fig.add_subplot(nrow, ncol, i)
        both = np.concatenate([dc, dr])
        both = both[np.isfinite(both)]
        lim = float(np.max(np.abs(both))) if both.size else 1.0
        bins = np.linspace(-lim, lim, 25) if lim > 0 else 10
        ax.hist(dc[np.isfinite(dc)], bins=bins, alpha=0.6, label="column P", color="#1f77b4")
        ax.hist(dr[np.isfinite(dr)], bins=bins, alpha=0.6, label="row L", color="#ff7f0e")
        ax.axvline(0, color="k", lw=0.8)
        ax.set_xlabel("residual (px)")
        ax.set_ylabel("points")
        ax.set_title(name, fontsize=10)
        ax.legend(fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def le68_figure(labels: Sequence[str], le68: np.ndarray, ci: np.ndarray, le90: np.ndarray,
                counts: Sequence[int]) -> Figure:
    """Toutin's figure: LE68 (with its bootstrap interval) and LE90 of the DEM against the
    lidar per class, metres."""
    fig = Figure(figsize=(max(6.0, 1.1 * len(labels) + 2), 4.5))
    ax = fig.add_subplot()
    x = np.arange(len(labels))
    err = np.abs(np.stack([le68 - ci[:, 0], ci[:, 1] - le68]))
    ax.bar(x - 0.2, le68, 0.4, yerr=np.where(np.isfinite(err), err, 0), capsize=3,
           label="LE68", color="#1f77b4")
    ax.bar(x + 0.2, le90, 0.4, label="LE90", color="#aec7e8")
    ax.set_xticks(x, [f"{lab}\n(n={c})" for lab, c in zip(labels, counts, strict=True)],
                  fontsize=8)
    ax.set_ylabel("|DEM - lidar| (m)")
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Linear error at 68 % and 90 % per class")
    return fig
