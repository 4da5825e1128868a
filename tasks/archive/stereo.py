"""Stereo pairs and blocks proposed from the scenes' own models (``gcpfree scenes``).

Every two scenes whose footprints overlap get their figures
(:func:`core.sensors.viewing.pair_geometry` at the mean of their two heights):

- **overlap** as a share of the smaller footprint (the intersection of the two corner
  quadrilaterals over the smaller one's area, in percent) and in km2;
- **B/H** from the two view vectors at the overlap's centre: the overlap's area centroid is
  projected into both images, each model's line of sight is taken there (through its ground
  points 500 m below and above), and ``B/H = 2 tan(c / 2)`` with ``c`` the angle between the
  two lines of sight (the convergence): the base over height of the symmetric pair with that
  convergence, which for views either side of the vertical is ``tan i1 + tan i2`` to within a
  few thousandths;
- the **incidence** difference at the overlap's centre, the **heading** difference (the
  along-track directions at the scene centres), the **date gap** (days; None when a product
  states no date), the **GSD ratio** (coarser over finer), the **sun** difference (when both
  metadata state it) and the two **band families**.

A pair is proposed as stereo when it meets every threshold of :class:`StereoCriteria`
(each failed one is its reason, written with its figures); the scene with the smaller
incidence is its left (fixed) image. **Blocks** are the connected components of the overlap
graph, every overlap of at least ``min_link_overlap_pct`` an edge, stereo or not (adjacent
scenes of a pass overlap by a few kilometres); a scene that overlaps no other is rejected
with that reason.
"""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from core.errors import GeometryError, InputError
from core.sensors.viewing import bearing_difference_deg, pair_geometry
from tasks.archive.scene_catalog import SCENES_FORMAT
from tasks.archive.scenes import GroundHeights, Rejection, Scene
from tasks.io.rasters import atomic_write_json

#: footprints further apart than this (degrees, their boxes') are not compared
_BOX_MARGIN_DEG = 0.05


@dataclass(frozen=True)
class StereoCriteria:
    """What makes two overlapping scenes a stereo pair (every threshold inclusive).

    Defaults, as a photogrammetrist screens an archive:

    - ``min_overlap_pct`` 30: a pair covering less than a third of its smaller scene gives a
      DEM of a strip;
    - B/H ``b_over_h_vhr`` 0.1-0.8 when the coarser GSD is at most ``vhr_gsd_m`` (2 m: Pleiades,
      SPOT 6-7, IKONOS: tri-stereo's narrow pairs, 0.1-0.25, still give heights to a metre
      and see into streets; beyond 0.8 occlusions take over), else ``b_over_h_spot`` 0.3-1.2
      (SPOT 1-5 across-track pairs from two dates up to +-27 deg, B/H up to 1.1-1.2 with the
      Earth's curvature; HRS along-track 0.8; below 0.3 a 10 m pixel gives heights worse than
      10 m);
    - ``max_incidence_diff_deg`` 30: beyond, one image's ground pixels are a third larger
      than the other's across track and the correlation windows stop matching;
    - ``max_heading_diff_deg`` 30: sun-synchronous passes over one place head the same way
      to a few degrees; more is another acquisition geometry (an agile platform's scan, an
      ascending pass) worth a look before it is paired;
    - ``max_date_gap_days`` 365: same-date (along-track) pairs are stereo pairs, and the
      archive's two-date pairs of one season or year still correlate (the tie points switch
      to orientation correlation when the suns differ); beyond a year the ground has
      changed;
    - ``max_gsd_ratio`` 2: a 5 m and a 10 m image still match at 10 m; 2.5 m against 10 m
      does not;
    - ``same_band_family``: panchromatic with panchromatic, multispectral with
      multispectral;
    - ``min_link_overlap_pct`` 1: the least overlap that ties two scenes into one block.
    """

    min_overlap_pct: float = 30.0
    b_over_h_vhr: tuple[float, float] = (0.1, 0.8)
    b_over_h_spot: tuple[float, float] = (0.3, 1.2)
    vhr_gsd_m: float = 2.0
    max_incidence_diff_deg: float = 30.0
    max_heading_diff_deg: float = 30.0
    max_date_gap_days: float = 365.0
    max_gsd_ratio: float = 2.0
    same_band_family: bool = True
    min_link_overlap_pct: float = 1.0

    def __post_init__(self) -> None:
        for name in ("b_over_h_vhr", "b_over_h_spot"):
            lo, hi = (float(v) for v in getattr(self, name))
            if not (0.0 <= lo <= hi and math.isfinite(hi)):
                raise InputError(f"B/H range {lo:g}..{hi:g} is empty; give MIN <= MAX, both "
                                 ">= 0 (--bh MIN MAX)")
            object.__setattr__(self, name, (lo, hi))
        for name, flag in (("min_overlap_pct", "--min-overlap"),
                           ("min_link_overlap_pct", "--min-link-overlap")):
            if not 0.0 <= getattr(self, name) <= 100.0:
                raise InputError(f"{flag} {getattr(self, name):g} is not a share of a scene; "
                                 "give 0 to 100 (%)")
        for name, flag in (("vhr_gsd_m", "--vhr-gsd"), ("max_incidence_diff_deg",
                           "--max-incidence-diff"), ("max_heading_diff_deg",
                           "--max-heading-diff"), ("max_date_gap_days", "--max-date-gap")):
            v = getattr(self, name)
            if not (v >= 0.0 and not math.isnan(v)):
                raise InputError(f"{flag} {v:g} must be 0 or more")
        if not self.max_gsd_ratio >= 1.0:
            raise InputError(f"--max-gsd-ratio {self.max_gsd_ratio:g} must be at least 1 "
                             "(coarser GSD over finer)")

    def b_over_h_range(self, gsd_m: float) -> tuple[tuple[float, float], str]:
        """The B/H range for a pair whose coarser GSD is ``gsd_m``, and its class."""
        if gsd_m <= self.vhr_gsd_m:
            return self.b_over_h_vhr, "vhr"
        return self.b_over_h_spot, "spot-like"


@dataclass(frozen=True)
class OverlapFigures:
    """Two overlapping scenes' figures (degrees, metres, km2, days); see the module docstring.
    ``*_left``/``*_right`` follow the pair's order; None: unknown (a product states no date
    or no sun)."""

    h_m: float
    lon_deg: float
    lat_deg: float
    overlap_pct: float
    overlap_km2: float
    b_over_h: float
    convergence_deg: float
    incidence_left_deg: float
    incidence_right_deg: float
    incidence_diff_deg: float
    heading_diff_deg: float
    date_gap_days: float | None
    gsd_ratio: float
    sun_elevation_diff_deg: float | None
    sun_azimuth_diff_deg: float | None
    band_families: tuple[str, str]
    resolution: str
    b_over_h_range: tuple[float, float]


@dataclass(frozen=True)
class Overlap:
    """Two scenes that overlap (``left`` has the smaller incidence), their figures, and why
    they are not a stereo pair (empty: they are one, ``pair_id``)."""

    left: str
    right: str
    figures: OverlapFigures
    reasons: tuple[str, ...]
    pair_id: str | None = None

    @property
    def stereo(self) -> bool:
        return not self.reasons


@dataclass(frozen=True)
class Block:
    """A connected component of overlapping scenes, and the stereo pairs inside it."""

    id: str
    scenes: tuple[str, ...]
    pairs: tuple[str, ...]


def _boxes_meet(a: Scene, b: Scene) -> bool:
    (a0, a1, a2, a3), (b0, b1, b2, b3) = a.bbox, b.bbox
    m = _BOX_MARGIN_DEG
    return a0 - m <= b2 and b0 - m <= a2 and a1 - m <= b3 and b1 - m <= a3


def _date_gap_days(a: Scene, b: Scene) -> float | None:
    ta, tb = a.acquisition.datetime, b.acquisition.datetime
    return None if ta is None or tb is None else abs((ta - tb).total_seconds()) / 86400.0


def overlap_figures(a: Scene, b: Scene, criteria: StereoCriteria) -> OverlapFigures | None:
    """The figures of scenes ``a`` (left) and ``b`` (right), None when they do not overlap
    at the mean of their heights."""
    if not _boxes_meet(a, b):
        return None
    h = 0.5 * (a.h_m + b.h_m)
    try:
        p = pair_geometry(a.loaded.model, a.size, b.loaded.model, b.size, h)
        q = pair_geometry(b.loaded.model, b.size, a.loaded.model, a.size, h)
    except GeometryError:
        return None
    coarse = max(a.gsd_m, b.gsd_m)
    bh_range, resolution = criteria.b_over_h_range(coarse)
    sun_el = sun_az = None
    if a.sun_deg is not None and b.sun_deg is not None:
        sun_el = abs(a.sun_deg[1] - b.sun_deg[1])
        sun_az = float(bearing_difference_deg(a.sun_deg[0], b.sun_deg[0]))
    return OverlapFigures(
        h_m=h, lon_deg=p.lon_deg, lat_deg=p.lat_deg,
        overlap_pct=min(max(p.overlap_pct, q.overlap_pct), 100.0),
        overlap_km2=p.overlap_area_m2 / 1e6, b_over_h=p.b_over_h,
        convergence_deg=p.convergence_deg, incidence_left_deg=p.incidence1_deg,
        incidence_right_deg=p.incidence2_deg,
        incidence_diff_deg=abs(p.incidence1_deg - p.incidence2_deg),
        heading_diff_deg=float(bearing_difference_deg(a.heading_deg, b.heading_deg)),
        date_gap_days=_date_gap_days(a, b), gsd_ratio=coarse / min(a.gsd_m, b.gsd_m),
        sun_elevation_diff_deg=sun_el, sun_azimuth_diff_deg=sun_az,
        band_families=(a.band_family, b.band_family), resolution=resolution,
        b_over_h_range=bh_range)


def stereo_reasons(f: OverlapFigures, c: StereoCriteria) -> tuple[str, ...]:
    """Every threshold of ``c`` the figures ``f`` fail, one phrase each (empty: stereo)."""
    out = []
    if f.overlap_pct < c.min_overlap_pct:
        out.append(f"overlap {f.overlap_pct:.1f} % of the smaller scene < {c.min_overlap_pct:g}")
    lo, hi = f.b_over_h_range
    if not lo <= f.b_over_h <= hi:
        out.append(f"B/H {f.b_over_h:.3f} outside {lo:g}-{hi:g} ({f.resolution})")
    if f.incidence_diff_deg > c.max_incidence_diff_deg:
        out.append(f"incidences differ by {f.incidence_diff_deg:.1f} deg > "
                   f"{c.max_incidence_diff_deg:g}")
    if f.heading_diff_deg > c.max_heading_diff_deg:
        out.append(f"headings differ by {f.heading_diff_deg:.1f} deg > "
                   f"{c.max_heading_diff_deg:g}")
    if f.date_gap_days is not None and f.date_gap_days > c.max_date_gap_days:
        out.append(f"{f.date_gap_days:.0f} days apart > {c.max_date_gap_days:g}")
    if f.gsd_ratio > c.max_gsd_ratio:
        out.append(f"GSD ratio {f.gsd_ratio:.2f} > {c.max_gsd_ratio:g}")
    if c.same_band_family and f.band_families[0] != f.band_families[1]:
        out.append(f"band families differ ({f.band_families[0]}, {f.band_families[1]})")
    return tuple(out)


def _ordered(a: Scene, b: Scene) -> tuple[Scene, Scene]:
    """The pair's left (fixed) image: the smaller incidence (the steadier planimetry)."""
    return (a, b) if (a.incidence_deg, a.id) <= (b.incidence_deg, b.id) else (b, a)


def find_overlaps(scenes: tuple[Scene, ...], criteria: StereoCriteria) -> tuple[Overlap, ...]:
    """Every overlapping couple of scenes with its figures, stereo pairs named by their
    ``left__right`` ids (made unique)."""
    out: list[Overlap] = []
    ids: set[str] = set()
    for i, a in enumerate(scenes):
        for b in scenes[i + 1:]:
            left, right = _ordered(a, b)
            f = overlap_figures(left, right, criteria)
            if f is None:
                continue
            reasons = stereo_reasons(f, criteria)
            pair_id = None
            if not reasons:
                pair_id, n = f"{left.id}__{right.id}", 2
                while pair_id in ids:
                    pair_id, n = f"{left.id}__{right.id}-{n}", n + 1
                ids.add(pair_id)
            out.append(Overlap(left.id, right.id, f, reasons, pair_id))
    return tuple(out)


def find_blocks(scenes: tuple[Scene, ...], overlaps: tuple[Overlap, ...],
                criteria: StereoCriteria) -> tuple[tuple[Block, ...], tuple[str, ...]]:
    """The blocks (largest first, then by their first scene id) and the ids of the scenes
    linked to no other (overlap of ``min_link_overlap_pct`` at least)."""
    links: dict[str, set[str]] = {s.id: set() for s in scenes}
    for o in overlaps:
        if o.stereo or o.figures.overlap_pct >= criteria.min_link_overlap_pct:
            links[o.left].add(o.right)
            links[o.right].add(o.left)
    seen: set[str] = set()
    components: list[tuple[str, ...]] = []
    for s in scenes:
        if s.id in seen or not links[s.id]:
            continue
        todo, members = [s.id], set()
        while todo:
            n = todo.pop()
            if n not in members:
                members.add(n)
                todo += links[n] - members
        seen |= members
        components.append(tuple(sorted(members)))
    components.sort(key=lambda c: (-len(c), c[0]))
    blocks = []
    for k, members in enumerate(components, start=1):
        inside = set(members)
        pairs = tuple(o.pair_id for o in overlaps if o.pair_id and o.left in inside)
        blocks.append(Block(f"block-{k}", members, pairs))
    alone = tuple(s.id for s in scenes if not links[s.id])
    return tuple(blocks), alone


# ---------------------------------------------------------------------------- the catalog


def paths_from(folder: Path) -> Any:  # Callable[[Path], str]
    """How a file is named in a document written into ``folder``: relative to it when it
    lies under it (the folder can move whole), else absolute."""
    base = os.path.abspath(folder)

    def rel(p: Path) -> str:
        p_abs = os.path.abspath(p)
        return os.path.relpath(p_abs, base) if p_abs.startswith(base + os.sep) else p_abs

    return rel


@dataclass(frozen=True, eq=False)
class SceneCatalog:
    """What ``gcpfree scenes`` found in ``root``: the scenes (every one in a block), the
    overlaps (stereo pairs among them), the blocks and the rejected files."""

    root: Path
    scenes: tuple[Scene, ...]
    overlaps: tuple[Overlap, ...]
    blocks: tuple[Block, ...]
    rejected: tuple[Rejection, ...]
    criteria: StereoCriteria
    heights: str

    @property
    def pairs(self) -> tuple[Overlap, ...]:
        return tuple(o for o in self.overlaps if o.stereo)

    def block_of(self, scene_id: str) -> str | None:
        return next((b.id for b in self.blocks if scene_id in b.scenes), None)

    def to_dict(self, catalog_path: Path) -> dict[str, Any]:
        """The catalog document; paths relative to ``catalog_path``'s folder."""
        rel = paths_from(Path(catalog_path).parent)

        by_id = {s.id: s for s in self.scenes}

        def pair(o: Overlap) -> dict[str, Any]:
            a, b = by_id[o.left], by_id[o.right]
            return {"id": o.pair_id, "left": rel(a.image), "right": rel(b.image),
                    "left_model": None if a.model is None else rel(a.model),
                    "right_model": None if b.model is None else rel(b.model),
                    "left_scene": a.id, "right_scene": b.id, "block": self.block_of(a.id),
                    "figures": asdict(o.figures)}

        return {
            "format": SCENES_FORMAT, "version": 1, "directory": rel(self.root),
            "heights": self.heights, "criteria": asdict(self.criteria),
            "scenes": [{**s.to_dict(rel), "block": self.block_of(s.id)} for s in self.scenes],
            "pairs": [pair(o) for o in self.pairs],
            "overlaps": [{"left": o.left, "right": o.right, "stereo": o.stereo,
                          "pair": o.pair_id, "reasons": list(o.reasons),
                          "figures": asdict(o.figures)} for o in self.overlaps],
            "blocks": [asdict(b) for b in self.blocks],
            "rejected": [{"path": rel(r.path), "reason": r.reason} for r in self.rejected],
        }


def propose(root: Path, scenes: tuple[Scene, ...], rejected: tuple[Rejection, ...],
            criteria: StereoCriteria, ground: GroundHeights) -> SceneCatalog:
    """The overlaps, stereo pairs and blocks of ``scenes``; a scene that overlaps no other
    joins the rejected files."""
    overlaps = find_overlaps(scenes, criteria)
    blocks, alone = find_blocks(scenes, overlaps, criteria)
    lonely = {s.id for s in scenes if s.id in alone}
    reason = (f"overlaps no other scene (at least {criteria.min_link_overlap_pct:g} % of the "
              "smaller footprint, at their mean height)")
    if not ground.given:
        reason += ("; at the models' own mean heights small crops can miss each other: give "
                   "--reference or --dem-dir")
    out_rejected = rejected + tuple(Rejection(s.image, reason) for s in scenes
                                    if s.id in lonely)
    kept = tuple(s for s in scenes if s.id not in lonely)
    linked = tuple(o for o in overlaps if o.left not in lonely and o.right not in lonely)
    return SceneCatalog(Path(root), kept, linked, blocks, out_rejected, criteria,
                        ground.describe())


# ---------------------------------------------------------------------------- writing


def stac_path(catalog_path: str | Path) -> Path:
    """The STAC ItemCollection written beside the catalog: ``CATALOG.stac.json``."""
    p = Path(catalog_path)
    return p.with_name(p.stem + ".stac.json")


def _media_type(path: Path) -> str:
    import pystac

    return pystac.MediaType.JPEG2000 if path.suffix.lower() == ".jp2" else \
        pystac.MediaType.GEOTIFF


def scene_items(cat: SceneCatalog, path: Path) -> list:  # list[pystac.Item]
    """One STAC item per scene: footprint, acquisition, the view extension's incidence and
    sun, platform and instrument, GSD; its image and model as assets (hrefs relative to
    ``path``'s folder)."""
    import pystac
    from pystac.extensions.view import ViewExtension

    from tasks.archive.stac import footprint_item

    rel = paths_from(Path(path).parent)
    items = []
    for s in cat.scenes:
        a = s.acquisition
        props: dict[str, Any] = {
            "gsd": s.gsd_m, "gcpfree:model_family": s.family,
            "gcpfree:band_family": s.band_family, "gcpfree:block": cat.block_of(s.id),
            "gcpfree:h_m": s.h_m, "gcpfree:height_source": s.height_source,
            "gcpfree:heading_deg": s.heading_deg,
            "gcpfree:sensor_azimuth_deg": s.sensor_azimuth_deg,
            "gcpfree:acquired_source": a.source}
        if a.satellite:
            props["platform"] = a.satellite.lower().replace(" ", "-")
        if a.instrument:
            props["instruments"] = [a.instrument.lower().replace(" ", "")]
        assets = {"image": pystac.Asset(rel(s.image),
                                        media_type=_media_type(s.image), roles=["data"],
                                        title="scene image")}
        if s.model is not None:
            assets["model"] = pystac.Asset(rel(s.model),
                                           roles=["metadata"], title="sensor model")
        item = footprint_item(s.id, list(s.footprint), a.datetime, props, assets)
        view = ViewExtension.ext(item, add_if_missing=True)
        view.apply(incidence_angle=s.incidence_deg,
                   sun_azimuth=None if s.sun_deg is None else s.sun_deg[0],
                   sun_elevation=None if s.sun_deg is None else s.sun_deg[1])
        items.append(item)
    return items


def write_scene_catalog(cat: SceneCatalog, out: str | Path) -> tuple[Path, Path]:
    """``out`` (the catalog JSON that ``gcpfree archive --catalog`` reads) and the STAC
    ItemCollection beside it (:func:`stac_path`), each written atomically."""
    from tasks.archive.stac import write_item_collection

    out = Path(out)
    items_path = stac_path(out)
    doc = cat.to_dict(out)
    doc["stac"] = paths_from(out.parent)(items_path)
    atomic_write_json(out, doc)
    write_item_collection(scene_items(cat, items_path), items_path)
    return out, items_path


# ---------------------------------------------------------------------------- the table


def _table(header: tuple[str, ...], rows: list[tuple[str, ...]], indent: str = "  "
           ) -> list[str]:
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h)
              for i, h in enumerate(header)]
    return [indent + "  ".join(v.ljust(w) for v, w in zip(r, widths, strict=True)).rstrip()
            for r in (header, *rows)]


def _days(v: float | None) -> str:
    """A date gap: days, or seconds under a day (a same-pass pair)."""
    if v is None:
        return "-"
    return f"{v * 86400:.0f} s" if v < 1.0 else f"{v:.1f}"


def catalog_lines(cat: SceneCatalog) -> list[str]:
    """The table ``gcpfree scenes`` prints: scenes, stereo pairs, blocks, the overlaps that
    are not stereo pairs with their reasons, the rejected files."""
    out = [(f"scenes         {cat.root}: {len(cat.scenes)} scene(s) in {len(cat.blocks)} "
            f"block(s), {len(cat.pairs)} stereo pair(s), {len(cat.rejected)} file(s) rejected"),
           f"heights        {cat.heights}"]
    if cat.scenes:
        out += ["", ("scene figures at the image centre (incidence, heading of the rows on "
                     "the ground, GSD) at the footprint's height h")]
        out += _table(("scene", "satellite", "acquired UTC", "band", "inc deg", "head deg",
                       "GSD m", "km2", "h m", "block"),
                      [(s.id, s.acquisition.satellite or "-",
                        (s.acquisition.utc or "-")[:19].replace("T", " "),
                        s.band_family[:3], f"{s.incidence_deg:.2f}", f"{s.heading_deg:.1f}",
                        f"{s.gsd_m:.2f}", f"{s.area_km2:.4g}", f"{s.h_m:.1f}",
                        cat.block_of(s.id) or "-") for s in cat.scenes])
    if cat.pairs:
        out += ["", ("stereo pairs (left fixed; overlap of the smaller scene; B/H from the "
                     "two view vectors at the overlap's centre)")]
        out += _table(("pair", "left", "right", "overlap %", "km2", "B/H", "conv deg",
                       "d inc", "d head", "days"),
                      [(o.pair_id or "", o.left, o.right, f"{o.figures.overlap_pct:.1f}",
                        f"{o.figures.overlap_km2:.4g}", f"{o.figures.b_over_h:.3f}",
                        f"{o.figures.convergence_deg:.2f}",
                        f"{o.figures.incidence_diff_deg:.1f}",
                        f"{o.figures.heading_diff_deg:.1f}",
                        _days(o.figures.date_gap_days)) for o in cat.pairs])
    for b in cat.blocks:
        out.append(f"{b.id:<14} {len(b.scenes)} scene(s), {len(b.pairs)} stereo pair(s): "
                   f"{', '.join(b.scenes)}")
    others = [o for o in cat.overlaps if not o.stereo]
    if others:
        out += ["", "overlaps that are not stereo pairs (they tie their block together)"]
        out += _table(("left", "right", "overlap %", "B/H", "why not a stereo pair"),
                      [(o.left, o.right, f"{o.figures.overlap_pct:.1f}",
                        f"{o.figures.b_over_h:.3f}", "; ".join(o.reasons)) for o in others])
    if cat.rejected:
        out += ["", "rejected"]
        out += _table(("file", "reason"), [(str(r.path), r.reason) for r in cat.rejected])
    return out
