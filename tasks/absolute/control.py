"""Task of step 4's ground control: the sources the adjustment takes, each a control set in
its own frame (:mod:`core.orientation.frames`): the SRTM surface-matching GCPs in the
reference's, the SAR-optical GCPs in the SAR scene's (its vertical the reference's). Refuses,
with the true reason, a pair with too little control; the estimator
(:func:`core.orientation.adjust.adjust`) decides how the sources combine."""

from __future__ import annotations

from dataclasses import dataclass

from prefect import task
from prefect.cache_policies import NO_CACHE

from core.errors import InsufficientDataError, InsufficientReliefError
from core.matching.relief import ReliefVerdict
from core.orientation.absolute import AbsoluteConfig
from core.orientation.adjust import ControlSet
from core.orientation.frames import REFERENCE, FramePrior
from core.orientation.sar_gcps import sar_frame
from core.points import ControlPoint
from tasks.absolute.sar_control import SarControl
from tasks.absolute.surface_match import SurfaceMatchResult


@dataclass(frozen=True, eq=False)
class GroundControl:
    """The control sets of one orientation, whether the SRTM windows are among them, and what
    the user should read about the choice."""

    sets: tuple[ControlSet, ...]
    srtm_used: bool
    notes: tuple[str, ...] = ()

    @property
    def gcps(self) -> tuple[ControlPoint, ...]:
        return tuple(p for s in self.sets for p in s.points)


@task(name="ground-control", cache_policy=NO_CACHE)
def ground_control(windows: SurfaceMatchResult, verdict: ReliefVerdict,
                   sar: SarControl | None, config: AbsoluteConfig) -> GroundControl:
    """The SRTM windows' GCPs where the relief verdict allows them (the reference's frame,
    ``config.reference_sigma_m``) and the SAR scene's (``sar``), as control sets.

    Raises InsufficientReliefError (too flat) or InsufficientDataError (too small, voids, too
    few GCPs) with the figures, when there is not enough of either."""
    if not verdict.enough and sar is None:  # the true reason: too flat, too small, voids
        raise (InsufficientReliefError if verdict.reason == "too_flat"
               else InsufficientDataError)(verdict.message())
    srtm_used = verdict.enough and bool(windows.gcps)
    notes: list[str] = []
    sets: list[ControlSet] = []
    if srtm_used:
        sets.append(ControlSet("surface", windows.gcps, FramePrior(
            REFERENCE, config.reference_sigma_m, source="the reference's stated registration "
                                                        "(--reference-sigma)")))
    if sar is not None:
        if not srtm_used:
            why = verdict.message() if not verdict.enough else \
                f"no window gave a GCP: {windows.counts()}"
            notes.append(f"SRTM surface matching refused ({why}); the orientation proceeds on "
                         "the SAR GCPs alone")
        if sar.gcps:
            sets.append(ControlSet("sar", sar.gcps, sar_frame(
                sar.results, sar.config.geolocation_sigma_m, config.reference_sigma_m[2])))
    n = sum(len(s.points) for s in sets)
    if n < config.min_gcps and sar is not None:
        raise InsufficientDataError(
            f"only {n} GCPs from SRTM and SAR together ({config.min_gcps} needed): surface "
            f"matching {windows.counts()}; SAR "
            f"{'; '.join(r.refused or str(r.counts()) for r in sar.results)}")
    if n < config.min_gcps:
        raise InsufficientDataError(
            f"only {n} surface-matching windows gave a GCP ({config.min_gcps} needed): "
            f"{windows.counts()}; the relative DEM does not correlate with the reference: "
            f"terrain too flat for its noise (median relief {verdict.relief_found_m:.1f} m "
            "per window), clouds, voids or a wrong reference")
    return GroundControl(tuple(sets), srtm_used, tuple(notes))
