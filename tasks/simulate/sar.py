"""Task of the scene simulator: a SAR product (ERS-like or Sentinel-1-like) of the truth world.

``DIR/sar.tif`` (uint16 amplitude, radar geometry: slant range for ERS-like, ground range for
Sentinel-1-like), its annotation ``DIR/sar.xml`` in the Sentinel-1 form (read by
:mod:`tasks.io.sentinel1` as real ones are) and the delivered model ``DIR/sar.json`` (the
annotation read back, so ``sar.tif`` finds its model as the optical images do); the truth in
``DIR/truth/``: ``sar_truth.json`` (the true model: true orbit, the drawn azimuth-time and
range-delay errors as its corrections), ``sar.json`` (mission figures, the drawn errors,
corner reflectors with their true image positions) and ``sar_mask.tif`` (1 shadow, 2 layover,
3 both, on the truth grid).

The numerics are :mod:`core.simulation.sar` and :mod:`core.simulation.sar_render`; here the
truth DSM and land cover are read in strips of rows with the halo the shadow test needs, the
strips' intensities summed into the image (held whole: the size of the product), and the
products written.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rasterio
from prefect import task
from rasterio.errors import NotGeoreferencedWarning

from core.errors import GcpFreeError, InputError
from core.jsonio import parse_json
from core.sensors.pushbroom import PushbroomModel
from core.sensors.sar import SarModel
from core.sensors.sentinel1 import parse_annotation
from core.simulation.hashing import derive_seed
from core.simulation.sar import (
    OrbitFit,
    SarModels,
    geolocation_grid,
    grsr_coefficients,
    mission,
    sar_models,
)
from core.simulation.sar_render import (
    DN_PER_AMPLITUDE,
    GroundBlock,
    add_window,
    point_targets,
    reflector_cells,
    render_block,
    speckle_and_noise,
    splat,
    to_dn,
)
from core.simulation.scene import SceneDef, footprint_points
from tasks.io.crs import Projection
from tasks.io.rasters import (
    CogItem,
    CogOptions,
    atomic_write_json,
    atomic_write_text,
    read_surface_window,
    write_arrays_cog,
)
from tasks.io.sentinel1 import AnnotationHeader, annotation_xml
from tasks.simulate.io import ScenePaths

STRIP_CELLS = 400_000  # oversampled ground cells rendered at once (memory ~0.3 GB)
REFLECTOR_RCS_M2 = 1e5  # a large trihedral corner reflector at C band (50 dBm2)
N_REFLECTORS = 5


@dataclass(frozen=True)
class SarPaths:
    """Where the SAR products of a simulated scene live."""

    root: Path

    @property
    def image(self) -> Path:
        return self.root / "sar.tif"

    @property
    def annotation(self) -> Path:
        return self.root / "sar.xml"

    @property
    def model(self) -> Path:
        return self.root / "sar.json"

    @property
    def truth_model(self) -> Path:
        return self.root / "truth" / "sar_truth.json"

    @property
    def record(self) -> Path:
        return self.root / "truth" / "sar.json"

    @property
    def mask(self) -> Path:
        return self.root / "truth" / "sar_mask.tif"

    def all(self) -> tuple[Path, ...]:
        return (self.annotation, self.model, self.truth_model, self.record, self.mask,
                self.image)


@dataclass(frozen=True)
class SarSummary:
    """What ``simulate --sar`` made, for printing."""

    image: str
    mission: str
    kind: str
    size: tuple[int, int]
    looks: float
    centre_error_m: float
    n_reflectors: int

    def lines(self) -> list[str]:
        return [
            (f"SAR              {self.image} ({self.mission}-like {self.kind.upper()}, "
             f"{self.size[0]}x{self.size[1]} px, {self.looks:g} looks, {self.n_reflectors} "
             "corner reflectors; annotation sar.xml)"),
            (f"SAR geolocation  delivered annotation error at the scene centre "
             f"{self.centre_error_m:.1f} m"),
        ]


def _footprint(scene: SceneDef, out: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The optical images' footprint points, each at the lowest and the highest truth height."""
    paths = ScenePaths(out)
    lo, hi = scene.dsm_range_m
    models = [PushbroomModel.from_json(paths.truth_model(n).read_text())
              for n in scene.image_names]
    lon, lat = footprint_points(models, lo, hi)
    return (np.concatenate([lon, lon]), np.concatenate([lat, lat]),
            np.concatenate([np.full(lon.size, lo), np.full(lon.size, hi)]))


def _render(scene: SceneDef, out: Path, models: SarModels, incidence_deg: float,
            oversample: int) -> tuple[np.ndarray, np.ndarray]:
    """Clean intensity image and layover/shadow mask (on the truth grid), strip by strip."""
    paths = ScenePaths(out)
    truth = models.truth
    t_end = truth.first_line_time_s + truth.n_rows * truth.line_interval_s
    fit = OrbitFit.of(truth.orbit, truth.first_line_time_s - 2.0, t_end + 2.0)
    grid = scene.grid
    lo, hi = scene.dsm_range_m
    # the shadow ray climbs 1/tan(incidence) per metre: reach the highest cell from the lowest
    inc = np.radians(min(incidence_deg + 15.0, 80.0))
    halo = math.ceil((hi - lo) * math.tan(inc) / grid.res_m) + 3
    image = np.zeros((truth.n_rows, truth.n_cols))
    mask = np.zeros(grid.shape, dtype=np.uint8)
    to_lonlat = Projection(scene.epsg).to_lonlat
    x_left, y_top, res = grid.x_left_m, grid.y_top_m, grid.res_m
    strip_rows = max(8, STRIP_CELLS // (grid.width * oversample**2))
    for r0 in range(0, grid.height, strip_rows):
        r1 = min(r0 + strip_rows, grid.height)
        bounds = (x_left, y_top - r1 * res, x_left + grid.width * res, y_top - r0 * res)
        dsm = read_surface_window(paths.dsm, bounds, margin_cells=halo, what="truth DSM")
        cls = read_surface_window(paths.landcover, bounds, margin_cells=halo,
                                  what="truth land cover")
        # window cell (i, j) is grid cell (i + top, j + left)
        top = round((y_top - res / 2 - dsm.y0_m) / res)
        left = round((dsm.x0_m - (x_left + res / 2)) / res)
        block = GroundBlock(dsm.z_m.astype(np.float64), np.nan_to_num(cls.z_m).astype(np.uint8),
                            dsm.x0_m, dsm.y0_m, res, r0 - top, r1 - top, -left,
                            grid.width - left)
        rb = render_block(truth, fit, block, to_lonlat, oversample, models.pixel_area_m2)
        add_window(image, rb.intensity, rb.col0, rb.row0)
        mask[r0:r1] = rb.shadow.astype(np.uint8) + 2 * rb.layover.astype(np.uint8)
    return image, mask


def _reflectors(scene: SceneDef, out: Path, models: SarModels, mask: np.ndarray, seed: int
                ) -> list[dict]:
    """Corner reflectors on cells free of layover and shadow: ground point (the truth DSM at
    the cell centre), true image position, intensity added."""
    paths = ScenePaths(out)
    g = scene.grid
    rows, cols = reflector_cells(mask, g.shape, N_REFLECTORS, np.random.default_rng(seed),
                                 border=max(g.shape) // 5)
    x, y = g.x_left_m + (cols + 0.5) * g.res_m, g.y_top_m - (rows + 0.5) * g.res_m
    with rasterio.open(paths.dsm) as src:  # the cells' own heights
        h = np.array([v[0] for v in src.sample(zip(x, y, strict=True))], dtype=np.float64)
    x, y, h = x[np.isfinite(h)], y[np.isfinite(h)], h[np.isfinite(h)]
    lon, lat = Projection(scene.epsg).to_lonlat(x, y)
    col, row, inten = point_targets(models.truth, lon, lat, h, REFLECTOR_RCS_M2,
                                    models.pixel_area_m2)
    return [{"lon_deg": float(a), "lat_deg": float(b), "h_m": float(c), "col": float(d),
             "row": float(e), "intensity": float(f)}
            for a, b, c, d, e, f in zip(lon, lat, h, col, row, inten, strict=True)]


@task(name="simulate-sar")
def simulate_sar(scene: SceneDef, out: Path, mission_name: str) -> SarSummary:
    """The SAR product of a simulated scene (see the module docstring); a rerun with the same
    mission resumes, another mission on the same folder is refused."""
    out = Path(out)
    m = mission(mission_name)
    sp = SarPaths(out)
    if scene.dsm_range_m is None:
        raise InputError(f"{out}: the truth surface is not built yet; run gcpfree simulate "
                         "without --sar first, or with it from the start")
    if sp.record.exists():
        old = parse_json(sp.record.read_text(), str(sp.record))
        if old.get("mission") != m.name:
            raise InputError(f"{out} already holds the {old.get('mission')} SAR product; "
                             "choose another --out or remove sar.* and truth/sar*")
        if all(p.exists() for p in sp.all()):
            return sar_summary(out)
    lon, lat, h = _footprint(scene, out)
    c = scene.centre
    preset = scene.preset_spec
    pixel_scale = max(preset.gsd_m / 10.0, 1.0)
    models = sar_models(m, lon, lat, h, (c.lon_deg, c.lat_deg, c.h_m), c.h_m, pixel_scale,
                        np.random.default_rng(derive_seed(scene.seed, "sar", m.name)))
    # the annotation, read back: the delivered model is what the reader gives
    grid = geolocation_grid(models.delivered, c.h_m)
    head = AnnotationHeader(
        product_type="GRD" if m.kind == "grd" else "SLC", swath="IW" if m.mode == "IW" else "S2",
        radar_frequency_hz=m.radar_frequency_hz, terrain_height_m=c.h_m,
        azimuth_pixel_spacing_m=models.ground_spacing_m[1],
        incidence_mid_deg=float(np.median(grid.incidence_deg)))
    text = annotation_xml(models.delivered, grid, head,
                          grsr_coefficients(models.delivered) if m.kind == "grd" else None)
    read_back = parse_annotation(text, str(sp.annotation)).model
    if read_back.to_json() != models.delivered.to_json():
        raise GcpFreeError("the written SAR annotation does not read back as its model (a time "
                           "not on the microsecond?); report this")
    oversample = max(1, math.ceil(2.0 * scene.grid.res_m / min(models.ground_spacing_m)))
    clean, mask = _render(scene, out, models, m.incidence_deg, oversample)
    intensity = speckle_and_noise(clean, models.looks, models.nesz, np.random.default_rng(
        derive_seed(scene.seed, "sar-speckle", m.name)))
    refl = _reflectors(scene, out, models, mask, derive_seed(scene.seed, "sar-reflectors"))
    win, c0, r0 = splat(np.array([r["col"] for r in refl]), np.array([r["row"] for r in refl]),
                        np.array([r["intensity"] for r in refl]))
    add_window(intensity, win, c0, r0)
    dn = to_dn(intensity)
    atomic_write_text(sp.annotation, text)
    atomic_write_text(sp.model, models.delivered.to_json(indent=1))
    atomic_write_text(sp.truth_model, models.truth.to_json(indent=1))
    record = {
        "mission": m.name, "mission_id": m.mission_id, "kind": models.truth.kind,
        "figures": {"altitude_m": m.altitude_m, "inclination_deg": m.inclination_deg,
                    "incidence_centre_deg": m.incidence_deg, "looks": models.looks,
                    "nesz_db": m.nesz_db, "pixel_scale": pixel_scale,
                    "ground_spacing_m": list(models.ground_spacing_m),
                    "oversample": oversample,
                    "error_sigmas": {"orbit_m": list(m.orbit_sigma_m),
                                     "azimuth_time_s": m.azimuth_time_sigma_s,
                                     "range_bias_m": m.range_bias_sigma_m}},
        "errors": models.errors.to_dict(),
        "centre_error_m": models.centre_error_m(c.h_m),
        "calibration": f"sigma0 = (DN / {DN_PER_AMPLITUDE:g})^2",
        "reflectors": refl, "reflector_rcs_m2": REFLECTOR_RCS_M2,
        "seed": scene.seed,
    }
    atomic_write_json(sp.record, record)
    g = scene.grid
    write_arrays_cog([CogItem(mask, sp.mask, CogOptions(
        transform=g.geotransform(), crs=f"EPSG:{scene.epsg}", nodata=None,
        resampling="nearest", tags={"values": "0 seen, 1 shadow, 2 layover, 3 both"}))])
    tags = {"annotation": sp.annotation.name, "calibration": record["calibration"],
            "seed": str(scene.seed), "mission": f"{m.name}-like (gcpfree simulate --sar)"}
    with warnings.catch_warnings():  # radar geometry: no georeferencing, as S1 measurements
        warnings.simplefilter("ignore", NotGeoreferencedWarning)
        write_arrays_cog([CogItem(dn, sp.image, CogOptions(nodata=0, tags=tags))])
    return sar_summary(out)


def sar_summary(out: Path) -> SarSummary:
    """The summary of the SAR product written in ``out``."""
    sp = SarPaths(Path(out))
    rec = parse_json(sp.record.read_text(), str(sp.record))
    model = SarModel.from_json(sp.model.read_text())
    return SarSummary(str(sp.image), rec["mission"], rec["kind"], (model.n_cols, model.n_rows),
                      float(rec["figures"]["looks"]), float(rec["centre_error_m"]),
                      len(rec["reflectors"]))
