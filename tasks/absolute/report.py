"""``report.json``, the record of ``gcpfree orient`` (steps 1-4), as a typed value: its
document :data:`REPORT` (:mod:`tasks.io.documents`: ``REPORT.write(path, report)``,
``REPORT.read(path)``, :func:`read_report` for a file or the folder holding it) writes and
reads the keys of :class:`OrientReport` and its sections
(:mod:`tasks.absolute.report_sections`), NaN as null.

Its keys (format ``gcpfree.orient``, version 1), as the README lists them:

- ``relative``: the relative orientation's record, ``relative/rel.json`` as written
  (format ``gcpfree.relative``; kept whole, its own writer owns its keys);
- ``relative_dem``: the relative DEM's summary (:class:`tasks.dense.dem.DemSummary`);
- ``surface_matching``: ``settings``, ``windows`` placed, ``counts`` by status, ``qualified``,
  ``relief`` (the verdict), ``windows_file``;
- ``gcps``: ``given``, ``used``, ``rejected``, ``rejected_ids`` (id, reason), ``file``;
- ``absolute``: per image (``images``) the parameters before and after with their sigmas and
  the GCP residuals; ``sigma0``, ``n_gcps``, ``rejected``, ``n_iterations``, ``converged``,
  ``corrections``, ``self_calibration`` (or null); ``frames`` (absent from older reports):
  each control frame's prior, estimated shift and sigma
  (:class:`core.orientation.frames.FrameEstimate`: ``name``, ``prior_sigma_m``, ``shift_m``,
  ``sigma_m``, ``observed``, ``source``, ``up_of``); since the true uncertainties (absent from
  older reports, read as None):
  ``variance_components`` (:meth:`core.orientation.uncertainty.VarianceComponents.to_dict`:
  per observation group, ``gcp_col`` and ``gcp_row`` or one ``gcp``, the ``factor`` that
  multiplies the GCPs' a-priori variances, its ``sigma_scale`` = sqrt(factor), ``n`` and
  ``redundancy``; ``split``: the F test's verdict), and ``predicted``, the check-point RMS
  predicted for users without check points: ``grid_points_per_side`` (9), ``heights_m`` (the
  5th, 50th, 95th percentiles of the GCPs kept), ``reference_sigma_m`` (the reference's
  registration error assumed, east, north, up; ``--reference-sigma``),
  ``correlated_ground_error`` (the GCPs' ground error correlated over kilometres, fitted on
  their residuals and propagated into the parameters' covariance: sigma per axis and length;
  :class:`core.orientation.ground_field.CorrelatedGroundError`) and per image (``images.<image>``)
  ``predicted_rms_col_px``/``predicted_rms_row_px`` over that grid of pixels spanning the
  image at those heights, with their terms ``adjustment_rms_*`` (the parameters' covariance),
  ``reference_rms_*`` (the reference's registration), ``unmodelled_rms_*`` (the model's own
  error: the GCP residuals' covariance between nearest neighbours in the image, when
  significant), ``noise_px`` (0), ``n`` points, and (since the frames) its two parts
  ``predicted_relative_rms_*`` and ``predicted_reference_rms_*``;
- ``models``: the oriented model files; ``reference``: the DEM used and its vertical datum,
  and ``registration_estimate`` where other control made the reference's own shift
  observable (absent otherwise); ``dsm``: the final DSM's files and summary;
- optional: ``sar`` (with ``--sar``; :meth:`tasks.absolute.sar_control.SarControl.summary`):
  the SAR scene, its mission and assumed geolocation error, the standard atmosphere's delay
  taken out of its range (``troposphere_m``), its ``frame``, the SAR GCPs' ``role`` (with
  SRTM, or alone where the relief verdict refused SRTM), per image the templates, counts by
  status, GCPs, matching noise and the SAR GCPs' residuals after the adjustment (RMS and mean,
  px); the points themselves are in ``sar_points.json``;
- optional: ``settings`` (absent from older reports): the inputs and options the orientation
  was made with (:meth:`flows.orient.OrientParams.settings`: the images, their models, the
  reference, the check points, every orientation option, paths made absolute); a rerun of
  ``gcpfree pair`` keeps the orientation only when they are the same;
- optional: ``check_points`` and ``check_points_before`` (per image, the paper's Table 2;
  ``check_points.<image>`` also gives ``predicted_rms_col_px`` and ``predicted_rms_row_px``,
  the RMS the adjustment predicts at those check points, beside the measured ``rms_col_px``
  and ``rms_row_px``, and its two parts ``predicted_relative_rms_*`` and
  ``predicted_reference_rms_*`` (each absent when there is no prediction): the covariance propagated through the model's partial derivatives at
  each point, the reference's registration error through the ground's, and the model's own
  error the GCP residuals show; the check points' own measurement noise is taken as 0, the
  simulator's being exact), and
  ``report``, the run report's own record (format ``gcpfree.report``, written by
  :mod:`tasks.report.build`; kept whole).

Pure dataclasses: no file is read or written here but through :data:`REPORT`. Another
format, or a version other than :data:`VERSION` (a newer one), is refused, never guessed.
The sections are typed in :mod:`tasks.absolute.report_sections` (importable from here).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from core.matching.peaks import MEASURE_NAMES
from core.orientation.checkpoints import CheckPointStats
from tasks.absolute.report_sections import (  # noqa: F401 (the sections, importable from here)
    Absolute,
    FinalDsm,
    GcpSummary,
    ImageFit,
    LensCalibration,
    Models,
    ReferenceUsed,
    RejectedGcp,
    SurfaceMatching,
    of_core,
)
from tasks.dense.dem import DemSummary
from tasks.io.documents import Document, layout

FORMAT = "gcpfree.orient"
VERSION = 1
FILE = "report.json"


def check_points_of(report: Mapping[str, Any]) -> dict[str, CheckPointStats] | None:
    """:func:`tasks.absolute.orientation.check_point_report`'s table as typed values."""
    return of_core(dict[str, CheckPointStats], report)


# ---------------------------------------------------------------------------- the report


@dataclass(frozen=True)
class OrientReport:
    """report.json, the record of ``gcpfree orient``: a section per step (the relative
    orientation, the relative DEM, surface matching, the GCPs, the absolute orientation, the
    oriented models, the reference, the final DSM), then, each absent when there is none, the
    check points after and before, the run report's record, the SAR control and the settings
    (every key: :mod:`tasks.absolute.report`)."""

    relative: Mapping[str, Any]
    relative_dem: DemSummary
    surface_matching: SurfaceMatching
    gcps: GcpSummary
    absolute: Absolute
    reference: ReferenceUsed
    dsm: FinalDsm
    models: Models = field(default_factory=Models)
    check_points: Mapping[str, CheckPointStats] | None = None
    check_points_before: Mapping[str, CheckPointStats] | None = None
    report: Mapping[str, Any] | None = None
    sar: Mapping[str, Any] | None = None
    settings: Mapping[str, Any] | None = None

    # keys given their own section in the run report (the others are listed as they are)
    SECTIONS = ("format", "version", "relative", "relative_dem", "surface_matching", "gcps",
                "absolute", "check_points", "check_points_before")
    RUN_REPORT_KEY = "report"

    def lines(self) -> list[str]:
        """The orientation's figures as ``gcpfree orient`` and ``gcpfree pair`` print them."""
        g, sm = self.gcps, self.surface_matching
        out = [(f"GCPs                  {g.used} used, {g.rejected} rejected ({sm.windows} "
                f"SRTM windows, {sm.qualified} with enough relief)")]
        if self.sar is not None:
            for name, s in self.sar.get("images", {}).items():
                res = (f", residuals P {s['residual_rms_col_px']:.3f} L "
                       f"{s['residual_rms_row_px']:.3f} px RMS"
                       if "residual_rms_col_px" in s else "")
                why = f": none, {s['refused']}" if s.get("refused") else ""
                out.append(f"GCPs from SAR {name:<6}  {s['gcps']} ({self.sar['role']}){why}"
                           f"{res}")
        for name, a in self.absolute.images.items():
            out.append(f"GCP residuals {name:<6}  P {a.rms_col_px:.3f} px  "
                       f"L {a.rms_row_px:.3f} px RMS")
        ties = self.absolute.tie_points
        if ties is not None:
            measure = self.relative.get("tie_point_search", {}).get("measure")
            by = f" ({MEASURE_NAMES.get(measure, measure)})" if measure else ""
            out.append(f"tie points            {ties['n']} in the adjustment{by}, parallax "
                       f"{ties['rms_px']:.3f} px RMS")
        lens = self.absolute.self_calibration
        if lens is not None:
            why = ""
            if lens.tie_points is not None and lens.tie_points.get("evidence"):
                why = (f" (tie-point parallax {lens.tie_points['rms_px_without']:.3f} -> "
                       f"{lens.tie_points.get('rms_px_with', lens.tie_points['rms_px_trial']):.3f}"
                       " px with them)")
            out.append("lens terms            " + (
                ", ".join(f"{n}: {', '.join(t)}" for n, t in lens.significant.items()) + why
                if lens.applied else "not applied: " + (lens.decision or "none significant")))
        at = self.absolute.along_track
        if at is not None:
            rows = ", ".join(f"{n} {at['rms_row_px_without'][n]:.3f} -> "
                             f"{at['rms_row_px_with'][n]:.3f}" for n in at["rms_row_px_with"])
            out.append(f"along-track attitude  {at['harmonics']} harmonics (BIC over "
                       f"{', '.join(map(str, at['orders_tried']))}); GCP rows {rows} px")
        for name, c in (self.check_points or {}).items():
            pred = ("" if c.predicted_rms_col_px is None else
                    f"; predicted {c.predicted_rms_col_px:.3f} / {c.predicted_rms_row_px:.3f}")
            if c.predicted_relative_rms_col_px is not None:
                pred += (f" (relative {c.predicted_relative_rms_col_px:.3f} / "
                         f"{c.predicted_relative_rms_row_px:.3f}, reference "
                         f"{c.predicted_reference_rms_col_px:.3f} / "
                         f"{c.predicted_reference_rms_row_px:.3f})")
            out.append(f"check points {name:<6}  P {c.rms_col_px:.3f} px  "
                       f"L {c.rms_row_px:.3f} px RMS ({c.n} points){pred}")
        est = self.reference.registration_estimate
        if est:
            out.append("reference's shift     " + " / ".join(
                f"{v:+.1f} +- {s:.1f}" for v, s in zip(est["shift_m"], est["sigma_m"],
                                                       strict=True))
                       + " m east / north / up, estimated against the other control and "
                         "removed")
        d = self.dsm.summary
        out.append(f"final DSM             {d.dem_path} ({d.resolution_m:g} m, EPSG:{d.epsg}, "
                   f"{d.completeness_pct:.1f} % complete) and {self.dsm.egm96} (EGM96)")
        return out

    def with_run_report(self, record: Mapping[str, Any] | None) -> OrientReport:
        """The same orientation with the run report's record (None: without one)."""
        return replace(self, report=None if record is None else dict(record))


# the format and version first, then the sections in the order gcpfree has written them
layout(OrientReport, computed={"format": lambda r: FORMAT, "version": lambda r: VERSION},
       order=("format", "version", "relative", "relative_dem", "surface_matching", "gcps",
              "absolute", "models"),
       omit_default=("check_points", "check_points_before", "report", "sar", "settings"))
REPORT: Document[OrientReport] = Document(FILE, OrientReport, format=FORMAT, version=VERSION,
                                          hint="give the report.json gcpfree orient wrote")


def read_report(path: str | Path) -> OrientReport:
    """:data:`REPORT` read from ``path``: a report.json, or the orient output folder holding
    it.

    Raises:
        InputError: missing, not JSON, or not an orientation report this gcpfree reads.
    """
    path = Path(path)
    return REPORT.read(path / FILE if path.is_dir() else path)
