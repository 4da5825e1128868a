"""The run report of ``gcpfree orient``: ``OUT/report.html`` and its Markdown twin
``OUT/report.md``, with PNG figures beside them in ``OUT/report_files/``, and the report's own
numbers added to ``OUT/report.json`` under the key ``report``.

Built from the products of an orient output folder (``report.json``, ``windows.json``,
``gcps.json``, the oriented models, the relative orientation's tie points, the relative DEM),
plus what the caller may add: the reference DEM the orientation used (profile and correlation
surface), the check points (their residual vectors) and an ``eval.json`` of ``gcpfree
evaluate`` (LE68 per class). Every number of ``report.json`` is in a table, but the relative
orientation's: a curated table of what a photogrammetrist checks (its full record is
``relative/rel.json``). The figures are the papers' (tie points on the image, a correlation
surface, a profile of the relative DEM against the reference, residual vectors, LE68 per class,
histograms, the relief verdict).

``report.json`` stays the orientation's: its keys are kept as they are and only ``report`` is
added (replaced on every report), holding what the report shows beyond them (the lidar
evaluation, the window and profile drawn, the figures, what was not available), so that
report.json holds every number of the report. A folder with no report.json gets none.

A missing or unreadable product never fails the run: the report says what is not available
and what it would have shown. The maths is in core
(:func:`core.matching.surface.correlation_surface`, the sensor models' ``project``); the reading in
:mod:`tasks.report.inputs`, the drawing in :mod:`tasks.report.figures`, the HTML and Markdown
in :mod:`tasks.report.doc`.
"""

from __future__ import annotations

import logging
import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import rasterio
from matplotlib.figure import Figure as MplFigure
from prefect import task
from prefect.cache_policies import NO_CACHE
from rasterio.enums import Resampling
from rasterio.errors import NotGeoreferencedWarning
from rasterio.windows import Window

from core.errors import GcpFreeError
from core.geodesy import ARCSEC
from core.matching.surface import SurfaceMatchConfig, correlation_surface
from core.points import ControlPoint
from tasks.absolute.orientation import NAMES, read_checkpoints
from tasks.absolute.report import FILE as JSON_NAME
from tasks.absolute.report import REPORT, OrientReport, read_report
from tasks.absolute.surface_match import read_window_cells
from tasks.io.crs import Projection
from tasks.io.rasters import atomic_write_bytes, atomic_write_text
from tasks.io.sensors import load_model
from tasks.report import figures as F
from tasks.report.doc import Block, Figure, Heading, Para, Table, to_html, to_markdown
from tasks.report.inputs import (
    MADE_REFERENCE,
    TIEPOINTS,
    ReportInputs,
    best_window,
    read_inputs,
    read_optional_json,
)
from tasks.report.tables import (
    SECTIONS,
    absolute_tables,
    check_point_table,
    dem_tables,
    evaluation_tables,
    gcp_tables,
    prediction_table,
    relative_tables,
    relief_verdict,
    summary_table,
    surface_tables,
)

log = logging.getLogger(__name__)

HTML_NAME, MD_NAME, FIGURES_DIR = "report.html", "report.md", "report_files"
JSON_KEY = OrientReport.RUN_REPORT_KEY  # the key of report.json the report writes
FORMAT = "gcpfree.report"
THUMB_PX = 1200  # longest side of the image thumbnail


@dataclass
class _Report:
    """The report being built: its blocks, the figures written, what was not available and
    the numbers it adds to report.json (``data``)."""

    out: Path
    orientation: OrientReport | None  # report.json; None: missing or unreadable
    blocks: list[Block] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)
    figures: list[Path] = field(default_factory=list)
    data: dict[str, Any] = field(default_factory=dict)

    def add(self, *blocks: Block) -> None:
        self.blocks.extend(blocks)

    def lack(self, what: str) -> None:
        """Note a product not available (in the summary and where the figure would be)."""
        self.missing.append(what)
        self.add(Para(f"Not available: {what}.", "bad"))

    def figure(self, name: str, fig: MplFigure, caption: str) -> None:
        path = atomic_write_bytes(self.out / FIGURES_DIR / f"{name}.png", F.png_bytes(fig))
        self.figures.append(path)
        self.add(Figure(f"{FIGURES_DIR}/{name}.png", caption))

    def section(self, title: str, build: Callable[[], None]) -> None:
        """A section; whatever goes wrong in it is said in the report, not raised."""
        self.add(Heading(title))
        try:
            build()
        except Exception as exc:  # a report never fails the run
            log.warning("report section %r incomplete", title, exc_info=True)
            self.lack(f"part of '{title}' could not be made ({type(exc).__name__}: {exc})")


def _tables(rep: _Report, key: str, make: Callable[[OrientReport], list[Block]]) -> None:
    """The tables of report.json's ``key``, or a note that report.json is not available."""
    if rep.orientation is not None:
        rep.add(*make(rep.orientation))
    else:
        rep.lack(f"report.json '{key}'")


def _points(col: np.ndarray, row: np.ndarray, label: str) -> F.Points:
    return F.Points(np.asarray(col, dtype=float), np.asarray(row, dtype=float), label)


# ---------------------------------------------------------------------------- sections


def _tie_points(rep: _Report, inp: ReportInputs) -> None:
    rel = rep.orientation.relative if rep.orientation is not None else {}
    if inp.ties is None or inp.tie_doc is None:
        return rep.lack(f"{TIEPOINTS.as_posix()} (the tie-point figure)")
    image = rel.get("left", {}).get("image")
    thumb, size = None, None
    if image and Path(image).is_file():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            with rasterio.open(image) as src:
                size = (src.width, src.height)
                k = max(1, math.ceil(max(size) / THUMB_PX))
                thumb = src.read(1, out_shape=(math.ceil(src.height / k),
                                               math.ceil(src.width / k)),
                                 resampling=Resampling.average,
                                 masked=True).astype(np.float64).filled(np.nan)
    else:
        rep.lack(f"the left image ({image or 'not named in rel.json'}): tie points drawn alone")
    tp, g = inp.tie_doc["tie_points"], inp.tie_doc["relative_ground"]
    idx, inl = np.asarray(g["index"], dtype=int), np.asarray(g["inlier"], dtype=bool)
    lc = np.array([np.nan if v is None else v for v in tp["left_col"]], dtype=float)
    lr = np.array([np.nan if v is None else v for v in tp["left_row"]], dtype=float)
    if size is None:
        size = (int(np.nanmax(lc)) + 1, int(np.nanmax(lr)) + 1)
    windows = []
    for status in dict.fromkeys(w["status"] for w in inp.windows or []):
        k = np.array([int(w["tie_point"]) for w in inp.windows or [] if w["status"] == status])
        windows.append((_points(inp.ties.left_col[k], inp.ties.left_row[k],
                                f"window {status} ({k.size})"), status))
    used = rejected = None
    if inp.gcps is not None:
        bad = ({r.id for r in rep.orientation.gcps.rejected_ids}
               if rep.orientation is not None else set())
        c, r, flag = _gcp_positions(inp.gcps, "left", bad)
        used = _points(c[~flag], r[~flag], f"GCP used ({int((~flag).sum())})")
        rejected = _points(c[flag], r[flag], f"GCP rejected ({int(flag.sum())})")
    fig = F.tie_points_figure(
        thumb, size, _points(lc[idx[inl]], lr[idx[inl]], f"tie point ({int(inl.sum())})"),
        _points(lc[idx[~inl]], lr[idx[~inl]], f"tie point rejected ({int((~inl).sum())})"),
        windows, used, rejected)
    rep.figure("tie_points", fig, "Tie points of the relative orientation over the left image; "
               "squares: surface-matching windows by outcome; dots: simulated GCPs.")


def _gcp_positions(gcps: tuple[ControlPoint, ...], name: str, bad: set[int]
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    pts = [g for g in gcps if name in g.image_points]
    return (np.array([g.image_points[name].col for g in pts], dtype=float),
            np.array([g.image_points[name].row for g in pts], dtype=float),
            np.array([g.id in bad for g in pts], dtype=bool))


def _profile(rep: _Report, inp: ReportInputs) -> None:
    if rep.orientation is not None:
        rep.add(*dem_tables(rep.orientation.relative_dem))
    else:
        rep.lack("report.json 'relative_dem'")
    dem_path = rep.out / "relative_dem.tif"
    if not dem_path.is_file():
        return rep.lack("relative_dem.tif (the profile figure)")
    if inp.reference is None:
        return rep.lack("the reference DEM (not given, or unreadable): no profile against it")
    best = best_window(inp)
    with rasterio.open(dem_path) as src:
        t, epsg = src.transform, src.crs.to_epsg()
        proj = Projection(epsg)
        if best is not None:
            _, y0 = proj.to_xy(np.array([best[1]]), np.array([best[2]]))
            r = int(np.clip((y0[0] - t.f) / t.e, 0, src.height - 1))
        else:
            r = src.height // 2
        h = src.read(1, window=Window(0, r, src.width, 1), masked=True)
        h = h.astype(np.float64).filled(np.nan)[0]
    x = t.c + (np.arange(h.size) + 0.5) * t.a
    y = np.full(h.size, t.f + (r + 0.5) * t.e)
    lon, lat = proj.to_lonlat(x, y)
    km = (x - x[0]) / 1000.0
    lines = [F.Profile(km, h, "relative DEM (relative orientation's frame)"),
             F.Profile(km, inp.reference.height_m(lon, lat), "reference DEM", "--")]
    title = f"Profile along DEM row {r} (UTM north {y[0]:.0f} m)"
    if best is not None:
        w = best[0]
        moved = inp.reference.height_m(lon + w["shift_lon_arcsec"] * ARCSEC,
                                       lat + w["shift_lat_arcsec"] * ARCSEC) - w["shift_h_m"]
        lines.append(F.Profile(km, moved, "reference brought into the relative frame by the "
                               "window's 3-D shift", ":"))
        title += (f"; window at tie point {w['tie_point']}: shift {w['shift_east_m']:.1f} m E, "
                  f"{w['shift_north_m']:.1f} m N, {w['shift_h_m']:.1f} m up")
    dsm = rep.out / "dsm.tif"
    if dsm.is_file():
        with rasterio.open(dsm) as src:
            hd = np.ma.filled(np.ma.concatenate(list(src.sample(zip(x, y, strict=True),
                                                                 indexes=1, masked=True)))
                              .astype(np.float64), np.nan)
        lines.append(F.Profile(km, hd, "final DSM (oriented models)", "-."))
    rep.data["profile"] = {"dem_row": r, "north_m": float(y[0]), "epsg": epsg,
                           "tie_point": best[0]["tie_point"] if best else None,
                           "final_dsm": dsm.is_file()}
    rep.figure("profile", F.profile_figure(lines, title),
               "The relative DEM against the reference along a west-east row of the DEM "
               "(Goncalves's Fig. 4): offset before surface matching, aligned once the "
               "window's shift is applied.")


def _surface_matching(rep: _Report, inp: ReportInputs) -> None:
    if rep.orientation is None:
        return rep.lack("report.json 'surface_matching'")
    sm = rep.orientation.surface_matching
    rep.add(*surface_tables(sm, inp.windows))
    if inp.windows is None:
        return rep.lack("windows.json (per-window table, relief and correlation figures)")
    v = sm.relief

    def arr(k: str) -> np.ndarray:
        return np.array([np.nan if w.get(k) is None else w[k] for w in inp.windows], dtype=float)

    rel_m, pred = arr("relief_m"), arr("predicted_precision_m")
    ok = np.isfinite(rel_m) & np.isfinite(pred)
    statuses = [w["status"] for w, k in zip(inp.windows, ok, strict=True) if k]
    rep.figure("relief", F.relief_figure(rel_m[ok], pred[ok], statuses,
                                         float(v.max_precision_m or 10.0),
                                         ("Enough relief" if v.enough else "Too little relief")
                                         + f": {v.n_qualified} windows qualify, "
                                         f"{v.n_needed} needed"),
               "Relief-sufficiency verdict: each window's relief against the precision it "
               "promises; windows below the dashed line qualify.")
    best = best_window(inp)
    if best is None:
        return rep.lack("a matched window with its tie point (correlation surface)")
    if inp.reference is None:
        return rep.lack("the reference DEM (not given, or unreadable): no correlation surface")
    w, lon, lat = best
    cfg = inp.surface
    clon, clat, h = read_window_cells(str(rep.out / "relative_dem.tif"), lon, lat, cfg.radius_m)
    shifts, rho = correlation_surface(clon, clat, h, (lon, lat), inp.reference, cfg)
    if not np.isfinite(rho).any():
        return rep.lack("valid correlations in the best window")
    iy, ix = np.unravel_index(int(np.nanargmax(rho)), rho.shape)
    peak = {"tie_point": w["tie_point"], "lon_deg": lon, "lat_deg": lat,
            "shift_max_arcsec": cfg.shift_max_arcsec, "shift_step_arcsec": cfg.shift_step_arcsec,
            "grid_peak_lon_arcsec": float(shifts[ix]), "grid_peak_lat_arcsec": float(shifts[iy]),
            "grid_peak_correlation": float(rho[iy, ix]),
            **{k: w.get(k) for k in ("shift_lon_arcsec", "shift_lat_arcsec", "correlation",
                                     "precision_m")}}
    rep.data["correlation_surface"] = peak
    rep.add(Table.flat(peak, "Window drawn: grid maximum and the refined shift (windows.json)"))
    rep.figure("correlation_surface", F.correlation_figure(
        shifts, rho, (w["shift_lon_arcsec"], w["shift_lat_arcsec"]),
        f"Window at tie point {w['tie_point']} (lon {lon:.4f}, lat {lat:.4f}): peak "
        f"correlation {w['correlation']:.3f}, precision {w['precision_m']:.1f} m"),
        "Correlation of the relative DEM with the reference over the grid of (dlon, dlat) "
        "shifts for the window with the sharpest peak (Goncalves's Fig. 5); + the refined "
        "peak.")


def _residuals(rep: _Report, name: str, pts: list[Any], flagged: set[int]
               ) -> F.Residuals | None:
    """Measured - projected positions of ``pts`` (GCPs or check points, with ``lon_deg``,
    ``lat_deg``, ``h_m``, ``image_points``) in image ``name`` under its oriented model."""
    path = rep.out / f"{name}.json"
    if not path.is_file():
        rep.lack(f"{name}.json (the oriented {name} model)")
        return None
    loaded = load_model(path)
    pts = [p for p in pts if name in p.image_points]
    lon, lat, h = (np.array([getattr(p, k) for p in pts], dtype=float)
                   for k in ("lon_deg", "lat_deg", "h_m"))
    c = np.array([p.image_points[name].col for p in pts], dtype=float)
    r = np.array([p.image_points[name].row for p in pts], dtype=float)
    pc, pr = loaded.model.project(lon, lat, h)
    return F.Residuals(name, loaded.size, c, r, c - pc, r - pr,
                       np.array([p.id in flagged for p in pts], dtype=bool))


def _gcps(rep: _Report, inp: ReportInputs) -> list[F.Residuals]:
    if rep.orientation is None:
        rep.lack("report.json 'gcps'")
        return []
    g = rep.orientation.gcps
    rep.add(*gcp_tables(g))
    if inp.gcps is None:
        rep.lack("gcps.json (GCP residual vectors)")
        return []
    bad = {r.id for r in g.rejected_ids}
    panels = [p for name in NAMES if (p := _residuals(rep, name, list(inp.gcps), bad))]
    if panels:
        rep.figure("gcp_residuals", F.residual_vectors_figure(
            panels, "GCP residuals after the absolute orientation (measured - projected)"),
            "Residual vectors at the simulated GCPs, magnified; red: rejected as blunders.")
    at = rep.orientation.absolute.along_track
    if at is not None:
        rep.add(Table.flat({k: at[k] for k in ("harmonics", "bic", "rms_row_px_without",
                                               "rms_row_px_with", "tie_rms_px_without",
                                               "tie_rms_px_with")},
                           "Along-track attitude: harmonics chosen by BIC"))
        rep.figure("row_profile", F.row_profile_figure(
            at["row_profile_without"], at["row_profile_with"],
            f"GCP row residuals against row: {at['harmonics']} along-track harmonics"),
            "The GCPs' row residuals averaged in ten bands of image rows, without and with the "
            "attitude's along-track profile (harmonics in time, as many as the data choose).")
    return panels


def _check_points(rep: _Report, checkpoints: Path | None,
                  gcp_panels: list[F.Residuals]) -> None:
    o = rep.orientation
    after, before = (o.check_points, o.check_points_before) if o is not None else (None, None)
    groups = [(f"GCPs {p.name} (used)", p.d_col[~p.flagged], p.d_row[~p.flagged])
              for p in gcp_panels]
    if o is None or after is None:
        rep.lack("check points (none given to the orientation): no independent check")
    else:
        rep.add(check_point_table(after, before))
        if any(s.predicted_rms_col_px is not None for s in after.values()):
            rep.add(prediction_table(after, o.absolute, o.reference.registration_estimate))
    if checkpoints is None:
        if after is not None:
            rep.lack("the check-point file (not passed to the report): no check-point vectors")
    else:
        cps = read_checkpoints(checkpoints)
        panels = [p for name in NAMES if (p := _residuals(rep, name, list(cps.points), set()))]
        groups += [(f"check points {p.name}", p.d_col, p.d_row) for p in panels]
        if panels:
            rep.figure("checkpoint_residuals", F.residual_vectors_figure(
                panels, "Check-point residuals after the orientation (measured - projected)"),
                "Residual vectors at the independent check points, magnified.")
    if groups:
        rep.figure("histograms", F.histogram_figure(groups, "Residual histograms (px)"),
                   "Histograms of the residuals in column (P) and row (L).")


def _evaluation(rep: _Report, evaluation: Path | None) -> None:
    if evaluation is None:
        return rep.lack("the lidar evaluation (not given: gcpfree evaluate writes an eval.json "
                        "to pass to the report)")
    ev = read_optional_json(Path(evaluation))
    if not isinstance(ev, dict) or not isinstance(ev.get("classes"), dict):
        return rep.lack(f"a readable evaluation file at {evaluation}")
    rep.data["evaluation"] = {"file": str(evaluation), **ev}
    rep.add(*evaluation_tables(ev))
    labels = ev.get("class_labels") or {}
    stats = {**ev["classes"], **({"all": ev["all"]} if ev.get("all") else {})}
    names = list(stats)

    def col(k: str) -> np.ndarray:
        return np.array([np.nan if stats[n].get(k) is None else stats[n][k] for n in names],
                        dtype=float)

    ci = np.array([[np.nan if v is None else v for v in (stats[n].get("le68_ci") or
                                                         [None, None])] for n in names],
                  dtype=float).reshape(-1, 2)
    rep.figure("le68", F.le68_figure([labels.get(n) or n for n in names], col("le68"), ci,
                                     col("le90"), [int(stats[n].get("count") or 0)
                                                   for n in names]),
               "LE68 (bootstrap interval) and LE90 of the DEM against the lidar per class "
               "(Toutin).")


@dataclass(frozen=True)
class ReportOutcome:
    """What :func:`write_report` wrote: the HTML and Markdown, report.json when it extended
    it (None: the folder has none), the figures, and what was not available."""

    html: Path
    markdown: Path
    json: Path | None
    figures: tuple[Path, ...]
    not_available: tuple[str, ...]

    def lines(self) -> list[str]:
        out = [f"report                {self.html}", f"markdown              {self.markdown}",
               f"figures               {len(self.figures)} in {self.html.parent / FIGURES_DIR}"]
        if self.json is not None:
            out.append(f"numbers               {self.json} (key '{JSON_KEY}')")
        out += [f"not available         {m}" for m in self.not_available]
        return out


def make_report(out_dir: str | Path, reference: str | Path | None = None,
                checkpoints: str | Path | None = None, evaluation: str | Path | None = None,
                *, reference_vertical: str = "auto",
                surface: SurfaceMatchConfig | None = None) -> ReportOutcome:
    """Write ``out_dir/report.html``, ``out_dir/report.md`` and their figures
    (``out_dir/report_files/*.png``) from the products of ``gcpfree orient`` in ``out_dir``,
    and add the report's numbers to ``out_dir/report.json`` under ``report`` (its other keys
    kept; no report.json is created).

    ``reference``: the reference DEM the orientation used (``reference_vertical`` as given
    to it; default the one it made from SRTM tiles in ``out_dir/relative/``), for the profile
    and the correlation surface; ``checkpoints``: the check-point file (residual vectors);
    ``evaluation``: an ``eval.json`` of ``gcpfree evaluate`` (LE68 per class); ``surface``:
    the surface-matching settings of the run (default ones otherwise). Anything missing is
    said in the report ("Not available: ..."), never raised.
    """
    out = Path(out_dir)
    rep = _Report(out, None)
    if not (out / JSON_NAME).is_file():
        rep.missing.append(f"{JSON_NAME} (the orientation did not finish?)")
    else:
        try:
            rep.orientation = read_report(out / JSON_NAME)
        except GcpFreeError as exc:
            rep.missing.append(f"{JSON_NAME} ({exc})")
    if reference is None and (out / MADE_REFERENCE).is_file():
        reference = out / MADE_REFERENCE
    orientation = rep.orientation
    rel = orientation.relative if orientation is not None else {}
    inputs = {"output_folder": str(out), "left_image": rel.get("left", {}).get("image"),
              "right_image": rel.get("right", {}).get("image"),
              "reference": str(reference) if reference else None,
              "checkpoints": str(checkpoints) if checkpoints else None,
              "evaluation": str(evaluation) if evaluation else None}
    rep.add(Heading("Inputs"), Table.of(("product", "path"), [
        [k.replace("_", " "), "not given" if v is None else str(v)] for k, v in inputs.items()]))
    inp = read_inputs(out, Path(reference) if reference else None, reference_vertical,
                      surface or SurfaceMatchConfig(), rep.missing, orientation)
    gcp_panels: list[F.Residuals] = []
    rep.section("Tie points", lambda: _tie_points(rep, inp))
    rep.section("Relative orientation",
                lambda: _tables(rep, "relative", lambda o: relative_tables(o.relative)))
    rep.section("Relative DEM against the reference", lambda: _profile(rep, inp))
    rep.section("Surface matching and relief", lambda: _surface_matching(rep, inp))
    rep.section("Simulated GCPs", lambda: gcp_panels.extend(_gcps(rep, inp)))
    rep.section("Absolute orientation",
                lambda: _tables(rep, "absolute", lambda o: absolute_tables(o.absolute)))
    rep.section("Check points", lambda: _check_points(
        rep, Path(checkpoints) if checkpoints else None, gcp_panels))
    rep.section("Accuracy against lidar", lambda: _evaluation(
        rep, Path(evaluation) if evaluation else None))
    rest = {k: v for k, v in (REPORT.dump(orientation) if orientation else {}).items()
            if k not in SECTIONS and k != JSON_KEY}
    if rest:
        rep.section("Other products", lambda: rep.add(Table.flat(rest, "Other entries")))
    title = f"gcpfree orient: {out.resolve().name}"
    blocks: list[Block] = [Heading("Summary"), summary_table(orientation)]
    if orientation is not None:
        blocks.append(relief_verdict(orientation.surface_matching.relief))
    if rep.missing:
        blocks.append(Para("Not in this report: " + "; ".join(rep.missing) + ".", "bad"))
    blocks += rep.blocks
    md = atomic_write_text(out / MD_NAME, to_markdown(title, blocks))
    html = atomic_write_text(out / HTML_NAME, to_html(title, blocks))
    for old in (out / FIGURES_DIR).glob("*.png"):  # figures of an earlier report, not this one
        if old not in rep.figures:
            old.unlink(missing_ok=True)
    js = None
    if orientation is not None:  # the orientation's keys as they are, the report's beside
        js = REPORT.write(out / JSON_NAME, orientation.with_run_report({
            "format": FORMAT, "version": 1, "html": HTML_NAME, "markdown": MD_NAME,
            "figures": {p.stem: f"{FIGURES_DIR}/{p.name}" for p in rep.figures},
            "inputs": inputs, "not_available": rep.missing, **rep.data}))
    return ReportOutcome(html, md, js, tuple(rep.figures), tuple(rep.missing))


@task(name="write-report", cache_policy=NO_CACHE)
def write_report(out_dir: str | Path, reference: str | Path | None = None,
                 checkpoints: str | Path | None = None, evaluation: str | Path | None = None,
                 *, reference_vertical: str = "auto",
                 surface: SurfaceMatchConfig | None = None) -> ReportOutcome:
    """:func:`make_report` as a Prefect task (the step of ``gcpfree orient``)."""
    return make_report(out_dir, reference, checkpoints, evaluation,
                       reference_vertical=reference_vertical, surface=surface)
