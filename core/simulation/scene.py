"""Scene definitions of the simulator: presets, truth models, delivered-metadata errors, the
scene record (:class:`SceneDef`, saved as scene.json) and how a scene is sized.

Pure numerics on the pushbroom model. The truth models carry what the delivered metadata
lack (lens distortion with ``lens``, high-frequency attitude jitter with ``jitter``); the
delivered models differ from the truth by attitude biases worth 100-300 m on the ground
at the scene centre and by attitude drifts, as archive SPOT metadata do. With ``realistic``
(``--errors realistic``, the default of the spot and hrs presets) they also have what real
products have (:mod:`core.simulation.realistic`): a low-frequency attitude profile measured by
quantised angular speeds, ephemeris and time-tag errors, detector calibration errors.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from core.dem import GeoDEM
from core.errors import CoverageError, InputError
from core.geodesy import BBox, geodetic_to_ecef, metres_per_degree
from core.geoid import GeoidGrid
from core.jsonio import parse_json, to_json
from core.points import GeoPoint
from core.sensors.footprint import footprint_lonlat
from core.sensors.linear_array import LensDistortion
from core.sensors.pushbroom import PushbroomModel
from core.sensors.pushbroom_synthetic import SyntheticSpec, synthetic_pushbroom
from core.simulation.hashing import derive_seed
from core.simulation.landcover import water_level_for_fraction
from core.simulation.realistic import RealisticErrors, realistic_models

FloatArray = NDArray[np.float64]


ERROR_MODES = ("realistic", "simple")


@dataclass(frozen=True)
class ImageSpec:
    """One image of a stereo pair: viewing angles and the sun of its date."""

    name: str
    incidence_deg: float  # across-track, + = satellite west of the scene, looking east
    pitch_deg: float  # along-track tilt, + = forward
    date: str
    sun_azimuth_deg: float
    sun_elevation_deg: float


@dataclass(frozen=True)
class Preset:
    """Image size, sampling and the pair's geometry."""

    name: str
    n_cols: int
    n_rows: int
    gsd_m: float
    truth_res_m: float  # spacing of the truth DSM/DTM grid
    images: tuple[ImageSpec, ImageSpec]
    lidar_strip_m: tuple[float, float] | None  # (across, along) size; None = whole scene
    lidar_spacing_m: float = 3.0
    spot_mission: int = 2  # the SPOT product the delivered metadata imitate (METADATA.DIM)
    spot_instrument: str = "HRV"
    default_errors: str = "realistic"  # ``--errors`` when not given: realistic or simple

    def __post_init__(self) -> None:
        if self.default_errors not in ERROR_MODES:
            raise InputError(f"preset {self.name!r}: default_errors must be one of {ERROR_MODES}")
        if self.n_cols < 16 or self.n_rows < 16 or self.gsd_m <= 0 or self.truth_res_m <= 0:
            raise InputError(f"preset {self.name!r}: image must be >= 16x16 px with positive GSD")


_ACROSS = (
    ImageSpec("left", 25.5, 0.0, "2023-07-12", 140.0, 63.0),
    ImageSpec("right", -20.0, 0.0, "2023-08-29", 158.0, 50.0),
)
PRESETS: dict[str, Preset] = {
    # SPOT 1-4 HRV across-track pair from two dates, 10 m panchromatic
    "spot": Preset("spot", 6000, 6000, 10.0, 10.0, _ACROSS, (5_000.0, 13_000.0)),
    # SPOT 5 HRS-like along-track pair, same pass (B/H about 0.8)
    "hrs": Preset(
        "hrs", 6000, 6000, 10.0, 10.0,
        (ImageSpec("left", 0.0, 20.0, "2023-07-12", 140.0, 63.0),
         ImageSpec("right", 0.0, -20.0, "2023-07-12", 140.0, 63.0)),
        (5_000.0, 13_000.0), spot_mission=5, spot_instrument="HRS",
    ),
    # SPOT 5 HRG across-track pair from two dates: 5 m panchromatic (the 2.5 m THR supermode
    # aside), 12000 detectors over a 60 km swath, steered within +-27 deg (the same two views as
    # spot, inside that range); four times the pixels of spot on the same ground
    "hrg": Preset("hrg", 12000, 12000, 5.0, 5.0, _ACROSS, (5_000.0, 13_000.0),
                  spot_mission=5, spot_instrument="HRG"),
    # the same physics at 600x600 px and 40 m, for CI
    # (lidar over the whole scene, its spacing scaled with the GSD to stay CI-sized)
    # (simple errors unless asked: the test suite's scenes and CI figures stand on them)
    "tiny": Preset("tiny", 600, 600, 40.0, 20.0, _ACROSS, None, lidar_spacing_m=20.0,
                   default_errors="simple"),
}


@dataclass(frozen=True)
class ErrorConfig:
    """Errors of the delivered metadata and of the truth that the metadata ignore."""

    centre_error_m: tuple[float, float] = (100.0, 300.0)  # attitude bias effect at the centre
    drift_m: float = 20.0  # typical ground drift over the scene from attitude rates (1 sigma)
    lens: bool = False  # truth camera has radial + decentering distortion the metadata lack
    lens_edge_px: float = 1.5  # distortion at the image edge, pixels
    jitter: bool = False  # truth attitude has high-frequency jitter
    jitter_rms_px: float = 0.3  # jitter amplitude as ground displacement, pixels RMS
    realistic: bool = False  # the errors of real products (core.simulation.realistic)

    def __post_init__(self) -> None:
        lo, hi = self.centre_error_m
        if not 0 <= lo <= hi:
            raise InputError(f"centre_error_m must be (min, max) with 0 <= min <= max, got {lo, hi}")
        if self.drift_m < 0 or self.lens_edge_px < 0 or self.jitter_rms_px < 0:
            raise InputError("drift, lens and jitter magnitudes must be >= 0")


def error_config(preset: str, mode: str | None = None, **kw: object) -> ErrorConfig:
    """The errors of a scene of ``preset`` for ``--errors`` ``mode`` (``"realistic"`` or
    ``"simple"``; None: the preset's default), other settings from ``kw``."""
    if preset not in PRESETS:
        raise InputError(f"unknown preset {preset!r}; choose one of {sorted(PRESETS)}")
    mode = PRESETS[preset].default_errors if mode is None else mode
    if mode not in ERROR_MODES:
        raise InputError(f"--errors must be one of {ERROR_MODES}, got {mode!r}")
    return ErrorConfig(realistic=mode == "realistic", **kw)  # type: ignore[arg-type]


@dataclass(frozen=True)
class InjectedErrors:
    """What the simulator did to one image's metadata (for the truth record)."""

    roll_bias_rad: float
    pitch_bias_rad: float
    yaw_bias_rad: float
    roll_rate_rad_s: float
    pitch_rate_rad_s: float
    yaw_rate_rad_s: float
    centre_error_m: float
    jitter: tuple[tuple[int, float, float, float], ...]
    distortion: LensDistortion
    realistic: RealisticErrors | None = None  # with ``--errors realistic``

    def to_dict(self) -> dict:
        d = asdict(self)
        d["jitter"] = [list(t) for t in self.jitter]
        d["distortion"] = self.distortion.to_dict()
        d.pop("realistic")
        if self.realistic is not None:
            d["realistic"] = self.realistic.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: dict) -> InjectedErrors:
        try:
            return cls(
                **{k: float(d[k]) for k in (
                    "roll_bias_rad", "pitch_bias_rad", "yaw_bias_rad", "roll_rate_rad_s",
                    "pitch_rate_rad_s", "yaw_rate_rad_s", "centre_error_m")},
                jitter=tuple((int(t[0]), float(t[1]), float(t[2]), float(t[3]))
                             for t in d["jitter"]),
                distortion=LensDistortion.from_dict(d["distortion"], "injected.distortion"),
                realistic=(RealisticErrors.from_dict(d["realistic"]) if "realistic" in d
                           else None),
            )
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise InputError(f"injected errors record is malformed ({exc!r}); the scene.json "
                             "was not written by this version of gcpfree simulate") from exc


def truth_model(
    spec: ImageSpec, preset: Preset, centre: tuple[float, float, float], cfg: ErrorConfig,
    rng: np.random.Generator,
) -> PushbroomModel:
    """The true geometry of one image (with the lens distortion and jitter the metadata lack)."""
    lon, lat, h = centre
    model = synthetic_pushbroom(SyntheticSpec(
        lon, lat, centre_h_m=h, n_cols=preset.n_cols, n_rows=preset.n_rows, gsd_m=preset.gsd_m,
        incidence_deg=spec.incidence_deg, pitch_deg=spec.pitch_deg,
        epoch_utc=f"{spec.date}T10:00:00Z",
    ))
    if cfg.lens:
        # radial k3 r^3 worth lens_edge_px at the edge of the detector line (r in normalised
        # focal-plane units, measured on this camera), decentering a tenth of it
        ex, ey = model.camera.detector_xy(np.array([0.0]))
        r_edge = float(np.hypot(ex[0], ey[0]))
        px = r_edge / (0.5 * (preset.n_cols - 1))  # one pixel in normalised units
        k3 = cfg.lens_edge_px * px / r_edge**3 * float(rng.choice([-1.0, 1.0]))
        p = 0.1 * cfg.lens_edge_px * px / r_edge**2
        model = replace(model, distortion=LensDistortion(
            k1=0.0, k3=k3, p1=p * rng.uniform(-1, 1), p2=p * rng.uniform(-1, 1)))
    if cfg.jitter:
        model = with_jitter(model, preset, cfg.jitter_rms_px, rng)
    return model


def with_jitter(
    model: PushbroomModel, preset: Preset, rms_px: float, rng: np.random.Generator
) -> PushbroomModel:
    """Add roll and pitch jitter: two tones per axis, periods of 30-600 lines (about 1-20 Hz
    for SPOT), each axis ``rms_px`` RMS as ground displacement (two tones of amplitude a
    have an RMS of a)."""
    amp_rad = rms_px * preset.gsd_m / _slant_range_m(model)
    terms = []
    for axis in (0, 1):  # roll moves the ground across track, pitch along track
        for _ in range(2):
            freq = 1.0 / (rng.uniform(30.0, 600.0) * model.line_period_s)
            terms.append((axis, float(amp_rad), float(freq), float(rng.uniform(0, 2 * np.pi))))
    return replace(model, attitude=replace(model.attitude, jitter=tuple(terms)))


def _slant_range_m(model: PushbroomModel) -> float:
    c, r = 0.5 * (model.n_cols - 1), 0.5 * (model.n_rows - 1)
    lon, lat = model.localize(c, r, 0.0)
    g = np.array(geodetic_to_ecef(lon, lat, 0.0)).ravel()
    pos, _ = model.orbit.interpolate(np.atleast_1d(model.line_time_s(r)))
    return float(np.linalg.norm(pos[0] - g))


def centre_displacement_m(a: PushbroomModel, b: PushbroomModel, h_m: float) -> float:
    """Ground distance between what two models localise for the centre pixel at height h."""
    c, r = 0.5 * (a.n_cols - 1), 0.5 * (a.n_rows - 1)
    pa = np.array(geodetic_to_ecef(*a.localize(c, r, h_m), h_m)).ravel()
    pb = np.array(geodetic_to_ecef(*b.localize(c, r, h_m), h_m)).ravel()
    return float(np.linalg.norm(pa - pb))


def delivered_model(
    truth: PushbroomModel, preset: Preset, cfg: ErrorConfig, rng: np.random.Generator,
    h_centre_m: float,
) -> tuple[PushbroomModel, InjectedErrors]:
    """The metadata as an archive delivers them: biased, drifting, no jitter, no distortion."""
    att = truth.attitude
    base = replace(truth, attitude=replace(att, jitter=()), distortion=LensDistortion())
    target = rng.uniform(*cfg.centre_error_m)
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    range_m = _slant_range_m(truth)
    duration = truth.n_rows * truth.line_period_s
    rates = rng.normal(size=3) * cfg.drift_m / (range_m * duration)

    def make(bias: FloatArray) -> PushbroomModel:
        def poly(c: tuple[float, ...], b: float, r: float) -> tuple[float, ...]:
            c = list(c) + [0.0] * max(0, 2 - len(c))
            c[0] += b
            c[1] += r
            return tuple(c)
        new_att = replace(
            base.attitude,
            roll_rad=poly(att.roll_rad, bias[0], rates[0]),
            pitch_rad=poly(att.pitch_rad, bias[1], rates[1]),
            yaw_rad=poly(att.yaw_rad, bias[2], rates[2]),
        )
        return replace(base, attitude=new_att)

    # scale the bias so the centre moves by the target distance (rates vanish at t_ref,
    # close to the centre line; two secant passes absorb the non-linearity)
    scale = target / range_m
    for _ in range(3):
        d = centre_displacement_m(truth, make(direction * scale), h_centre_m)
        if d <= 0:
            raise InputError("the injected attitude bias does not move the scene; check the preset")
        scale *= target / d
    delivered = make(direction * scale)
    err = centre_displacement_m(truth, delivered, h_centre_m)
    b = direction * scale
    return delivered, InjectedErrors(
        float(b[0]), float(b[1]), float(b[2]), float(rates[0]), float(rates[1]), float(rates[2]),
        err, tuple(att.jitter), truth.distortion,
    )


# ---------------------------------------------------------------------------- the scene


@dataclass(frozen=True)
class TruthGrid:
    """The north-up grid of the truth rasters in the scene's UTM zone (metres).

    ``(x_left_m, y_top_m)`` is the top-left corner of the top-left cell; cells are ``res_m``
    squares, ``width`` columns by ``height`` rows.
    """

    x_left_m: float
    y_top_m: float
    res_m: float
    width: int
    height: int

    def __post_init__(self) -> None:
        if not (self.res_m > 0 and self.width > 0 and self.height > 0):
            raise InputError(f"a truth grid needs res_m > 0 and a positive size, got {self}")

    @property
    def shape(self) -> tuple[int, int]:
        return int(self.height), int(self.width)

    def geotransform(self) -> tuple[float, float, float, float, float, float]:
        """Affine coefficients (a, b, c, d, e, f) with the origin at the top-left corner."""
        return (self.res_m, 0.0, self.x_left_m, 0.0, -self.res_m, self.y_top_m)

    def bounds_m(self) -> tuple[float, float, float, float]:
        """(x_min, y_min, x_max, y_max) of the grid's outer edges."""
        return (self.x_left_m, self.y_top_m - self.height * self.res_m,
                self.x_left_m + self.width * self.res_m, self.y_top_m)

    def cell_centres(self, r0: int, r1: int, c0: int, c1: int) -> tuple[FloatArray, FloatArray]:
        """(x, y) of the centres of rows r0..r1-1 and columns c0..c1-1, as 2-D arrays."""
        x = self.x_left_m + (np.arange(c0, c1) + 0.5) * self.res_m
        y = self.y_top_m - (np.arange(r0, r1) + 0.5) * self.res_m
        xx, yy = np.meshgrid(x, y)
        return xx, yy

    @classmethod
    def covering(cls, x_m: FloatArray, y_m: FloatArray, res_m: float, margin_m: float) -> TruthGrid:
        """The grid of ``res_m`` cells, snapped to multiples of ``res_m``, that covers the points
        with ``margin_m`` to spare on every side."""
        x0 = np.floor((x_m.min() - margin_m) / res_m) * res_m
        y1 = np.ceil((y_m.max() + margin_m) / res_m) * res_m
        width = int(np.ceil((x_m.max() + margin_m - x0) / res_m))
        height = int(np.ceil((y1 - (y_m.min() - margin_m)) / res_m))
        return cls(float(x0), float(y1), float(res_m), width, height)

    def to_list(self) -> list[float | int]:
        return [self.x_left_m, self.y_top_m, self.res_m, self.width, self.height]

    @classmethod
    def from_list(cls, v: list) -> TruthGrid:
        x0, y0, res, w, h = v
        return cls(float(x0), float(y0), float(res), int(w), int(h))


@dataclass(frozen=True)
class SceneDef:
    """Everything later steps need about a simulated scene; saved as DIR/truth/scene.json.

    ``dem_window`` is the part of the DEM read (degrees), ``dem_vertical`` the datum of its
    heights (``egm96`` or ``ellipsoidal``, converted to orthometric when read) and
    ``dem_vertical_source`` what decided it; relief is scaled by
    ``relief_factor`` around the orthometric height ``H_ref_m``; ``centre`` is the point the
    centre pixels see; ``epsg`` the UTM zone of the truth ``grid``; ``dsm_range_m`` the
    ellipsoidal range of the truth DSM once built; ``injected`` the metadata errors per image.
    """

    preset: str
    seed: int
    dem_path: str
    dem_window: BBox
    relief_factor: float
    H_ref_m: float
    centre: GeoPoint
    epsg: int
    grid: TruthGrid
    water_level_m: float | None
    bits: int
    date_change: float
    errors: ErrorConfig
    image_names: tuple[str, str]
    dsm_range_m: tuple[float, float] | None = None
    injected: Mapping[str, InjectedErrors] = field(default_factory=dict)
    dem_vertical: str = "egm96"
    dem_vertical_source: str = "SRTM: EGM96"

    @property
    def preset_spec(self) -> Preset:
        return PRESETS[self.preset]

    def to_dict(self) -> dict[str, Any]:
        """The scene.json layout (keys and value shapes are a documented output)."""
        return {
            "preset": self.preset, "seed": self.seed, "dem_path": self.dem_path,
            "dem_window": list(self.dem_window.as_tuple()), "relief_factor": self.relief_factor,
            "H_ref_m": self.H_ref_m, "centre": self.centre.to_list(), "epsg": self.epsg,
            "grid": self.grid.to_list(), "water_level_m": self.water_level_m, "bits": self.bits,
            "date_change": self.date_change, "errors": asdict(self.errors),
            "image_names": list(self.image_names),
            "dsm_range_m": None if self.dsm_range_m is None else list(self.dsm_range_m),
            "injected": {k: v.to_dict() for k, v in self.injected.items()},
            "dem_vertical": self.dem_vertical, "dem_vertical_source": self.dem_vertical_source,
        }

    def to_json(self) -> str:
        return to_json(self.to_dict(), indent=1)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> SceneDef:
        try:
            errors = dict(d["errors"])
            errors["centre_error_m"] = tuple(errors["centre_error_m"])
            rng = d.get("dsm_range_m")
            return cls(
                preset=str(d["preset"]), seed=int(d["seed"]), dem_path=str(d["dem_path"]),
                dem_window=BBox(*(float(v) for v in d["dem_window"])),
                relief_factor=float(d["relief_factor"]), H_ref_m=float(d["H_ref_m"]),
                centre=GeoPoint.from_list(d["centre"]), epsg=int(d["epsg"]),
                grid=TruthGrid.from_list(d["grid"]),
                water_level_m=None if d["water_level_m"] is None else float(d["water_level_m"]),
                bits=int(d["bits"]), date_change=float(d["date_change"]),
                errors=ErrorConfig(**errors),
                image_names=tuple(str(n) for n in d["image_names"]),  # type: ignore[arg-type]
                dsm_range_m=None if rng is None else (float(rng[0]), float(rng[1])),
                injected={str(k): InjectedErrors.from_dict(v) for k, v in d["injected"].items()},
                dem_vertical=str(d.get("dem_vertical", "egm96")),
                dem_vertical_source=str(d.get("dem_vertical_source", "SRTM: EGM96")),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"scene definition is malformed ({exc!r}); it was not written by "
                             "this version of gcpfree simulate") from exc

    @classmethod
    def from_json(cls, text: str) -> SceneDef:
        return cls.from_dict(parse_json(text, "scene.json"))


def dem_window(preset: Preset, lon_deg: float, lat_deg: float) -> BBox:
    """A lon/lat window around the scene centre wide enough for both footprints of ``preset``
    (1.6 image half-widths plus 3 km); :func:`footprint_points` checks it afterwards."""
    half_m = 0.5 * max(preset.n_cols, preset.n_rows) * preset.gsd_m * 1.6 + 3000.0
    m_lon, m_lat = metres_per_degree(lat_deg)
    half_lat, half_lon = float(half_m / m_lat), float(half_m / m_lon)
    return BBox(lon_deg - half_lon, lat_deg - half_lat, lon_deg + half_lon, lat_deg + half_lat)


def scale_relief(H_m: ArrayLike, H_ref_m: float, relief_factor: float) -> FloatArray:
    """Heights with their relief scaled by ``relief_factor`` around ``H_ref_m``."""
    return H_ref_m + relief_factor * (np.asarray(H_m, dtype=np.float64) - H_ref_m)


@dataclass(frozen=True)
class TerrainLevels:
    """Heights that size a scene: metres, ellipsoidal except ``H_ref_m`` (orthometric)."""

    H_ref_m: float  # median orthometric height of the DEM window (relief scaled around it)
    h_centre_m: float  # terrain under the scene centre
    h_lo_m: float  # below the lowest terrain
    h_hi_m: float  # above the highest canopy and roof
    water_level_m: float  # level below which 2 % of the window lies


def terrain_levels(H_m: FloatArray, transform: tuple[float, ...], geoid: GeoidGrid,
                   lon_deg: float, lat_deg: float, relief_factor: float) -> TerrainLevels:
    """The levels of a DEM window (orthometric ``H_m`` on a geotransform ``(a, b, c, d, e, f)``,
    north-up, NaN voids) after relief scaling, and the ellipsoidal height under the centre."""
    if np.isnan(H_m).all():
        raise InputError(f"the DEM has no valid height around {lon_deg:.4f}, {lat_deg:.4f}")
    H_ref = float(np.nanmedian(H_m))
    Hs = scale_relief(H_m, H_ref, relief_factor)
    h_centre = float(GeoDEM.from_transform(Hs, transform).height_m(lon_deg, lat_deg)
                     + geoid.undulation_m(lon_deg, lat_deg))
    if not np.isfinite(h_centre):
        raise InputError(f"the scene centre {lon_deg:.4f}, {lat_deg:.4f} falls on a DEM void or "
                         "outside the DEM; choose another --center")
    a, _, c, _, e, f = transform[:6]
    rows, cols = np.mgrid[0 : H_m.shape[0], 0 : H_m.shape[1]]
    h_nodes = Hs + geoid.undulation_m(c + (cols + 0.5) * a, f + (rows + 0.5) * e)
    return TerrainLevels(
        H_ref_m=H_ref, h_centre_m=h_centre,
        h_lo_m=float(np.nanmin(h_nodes)) - 20.0,
        h_hi_m=float(np.nanmax(h_nodes)) + 60.0,  # canopy, buildings, detail
        water_level_m=water_level_for_fraction(h_nodes, 0.02),
    )


@dataclass(frozen=True, eq=False)
class ImageModels:
    """One image of a simulated pair: its true geometry, its metadata, what differs."""

    truth: PushbroomModel
    delivered: PushbroomModel
    injected: InjectedErrors


def scene_models(preset: Preset, centre: GeoPoint, errors: ErrorConfig,
                 seed: int) -> dict[str, ImageModels]:
    """Truth and delivered models of each image of ``preset``, drawn from ``seed`` (with
    ``errors.realistic``, also the errors of :mod:`core.simulation.realistic`)."""
    out = {}
    for spec in preset.images:
        rng = np.random.default_rng(derive_seed(seed, "geometry", spec.name))
        t = truth_model(spec, preset, (centre.lon_deg, centre.lat_deg, centre.h_m), errors, rng)
        d, inj = delivered_model(t, preset, errors, rng, centre.h_m)
        if errors.realistic:  # its own stream: the simple errors above stay as they were
            t, d, real = realistic_models(
                t, d, np.random.default_rng(derive_seed(seed, "realistic", spec.name)),
                preset.spot_mission, preset.spot_instrument)
            inj = replace(inj, realistic=real,
                          centre_error_m=centre_displacement_m(t, d, centre.h_m))
        out[spec.name] = ImageModels(t, d, inj)
    return out


def footprint_points(models: list[PushbroomModel], h_lo_m: float,
                     h_hi_m: float) -> tuple[FloatArray, FloatArray]:
    """(lon, lat) along the edges of every image at both heights: the scene's ground extent."""
    lons, lats = zip(*(footprint_lonlat(m, m.n_cols, m.n_rows, (h_lo_m, h_hi_m)) for m in models),
                     strict=True)
    return np.concatenate(lons), np.concatenate(lats)


def check_window_covers(window: BBox, lon: FloatArray, lat: FloatArray, dem_name: str) -> None:
    """CoverageError when the footprint points fall outside the DEM window read."""
    need = BBox(float(lon.min()), float(lat.min()), float(lon.max()), float(lat.max()))
    if not window.contains(need):
        raise CoverageError(
            f"the DEM does not cover the simulated scene: it needs lon {need.lon_min:.4f}.."
            f"{need.lon_max:.4f}, lat {need.lat_min:.4f}..{need.lat_max:.4f} but {dem_name} gives "
            f"lon {window.lon_min:.4f}..{window.lon_max:.4f}, lat {window.lat_min:.4f}.."
            f"{window.lat_max:.4f}; use a larger DEM, a smaller preset or another --center"
        )
