"""Flow ``orient-pair``: the whole chain for one stereo pair, either sensor family, resumable.

orientation (``flows.orient``: relative orientation, relative DEM, SRTM surface matching, GCPs,
absolute orientation, final DSM) -> an ortho of each image over the final DSM's reference ->
ortho-vs-ortho check -> lidar evaluation (when lidar is given) -> report -> STAC catalog ->
``OUT/pair.json``, the manifest written last.

Each step checks its products before running: a product that exists and reads back (JSON that
parses with the expected format, a raster that opens with its size) is kept, so a rerun of an
interrupted pair resumes at the first missing step. :func:`pair_complete` reads the manifest
and checks every product it lists.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from prefect import flow, task
from prefect.cache_policies import NO_CACHE

from core.surface_match import SurfaceMatchConfig

FORMAT = "gcpfree.pair"
MANIFEST = "pair.json"


@dataclass(frozen=True)
class PairParams:
    """One pair to process (see ``gcpfree orient`` for the orientation options).

    ``lidar`` (LAS/LAZ) and ``landcover`` (a class raster) drive the evaluation; without lidar
    the pair ends with the ortho check. ``checkpoints``: independent points for the check-point
    table. ``pair_id`` names the STAC items (default: OUT's folder name).
    """

    left: Path
    right: Path
    out: Path
    left_model: Path | None = None
    right_model: Path | None = None
    srtm_dir: Path | None = None
    reference: Path | None = None
    lidar: Path | None = None
    landcover: Path | None = None
    checkpoints: Path | None = None
    self_calibrate: bool = False
    workers: int | None = None
    progress: bool = False
    band: int | None = None
    reference_vertical: str = "auto"
    lidar_vertical: str = "auto"
    corrections: str = "linear"
    pair_id: str | None = None
    surface: SurfaceMatchConfig | None = None
    spacing_m: float | None = None
    min_windows: int = 8


@dataclass(frozen=True, eq=False)
class PairOutcome:
    """What :func:`orient_pair_flow` wrote: the manifest and the steps it skipped."""

    manifest_path: Path
    manifest: dict[str, Any]
    skipped: tuple[str, ...]

    def lines(self) -> list[str]:
        m = self.manifest
        out = [f"pair                  {m['pair_id']}: {self.manifest_path}"]
        if self.skipped:
            out.append(f"resumed               kept {', '.join(self.skipped)}")
        out += self.figures()
        out.append("products              " + ", ".join(m["products"].values()))
        return out

    def figures(self) -> list[str]:
        """The headline figures, read back from the products."""
        out_dir = self.manifest_path.parent
        lines: list[str] = []
        try:
            from flows.orient import OrientOutcome

            report = json.loads((out_dir / "report.json").read_text())
            lines += OrientOutcome(out_dir / "report.json", report).lines()[1:]
        except (OSError, ValueError, KeyError):
            pass
        try:
            c = json.loads((out_dir / "ortho_compare.json").read_text())["px"]
            lines.append(f"ortho discrepancy     median {c['median_norm']:.2f} px, "
                         f"95th percentile {c['p95_norm']:.2f} px (left vs right ortho)")
        except (OSError, ValueError, KeyError, TypeError):
            pass
        try:
            a = json.loads((out_dir / "eval.json").read_text())["all"]
            lines.append(f"DSM vs lidar          LE68 {a['le68']:.2f} m, NMAD {a['nmad']:.2f} m, "
                         f"bias {a['mean']:+.2f} m ({a['count']} points; per class in "
                         "eval.json)")
        except (OSError, ValueError, KeyError, TypeError):
            pass
        return lines


# ----------------------------------------------------------------------------- validity


def _json_ok(path: Path, fmt: str | None = None) -> bool:
    try:
        doc = json.loads(path.read_text())
    except (OSError, ValueError):
        return False
    return fmt is None or (isinstance(doc, dict) and doc.get("format") == fmt)


def _raster_ok(path: Path) -> bool:
    import rasterio

    try:
        with rasterio.open(path) as src:
            return src.width > 0 and src.height > 0 and src.crs is not None
    except (OSError, rasterio.errors.RasterioError):
        return False


def product_ok(path: Path) -> bool:
    """True when ``path`` exists and reads back (rasters open, JSON parses)."""
    if not path.is_file():
        return False
    if path.suffix.lower() in (".tif", ".tiff"):
        return _raster_ok(path)
    if path.suffix.lower() == ".json":
        return _json_ok(path)
    return path.stat().st_size > 0


# the orientation's products: manifest key -> file in OUT
ORIENT_PRODUCTS = {"report": "report.json", "left_model": "left.json",
                   "right_model": "right.json", "gcps": "gcps.json", "dsm": "dsm.tif",
                   "dsm_egm96": "dsm_egm96.tif", "relative_dem": "relative_dem.tif"}


def orientation_done(out: Path) -> bool:
    """The orientation's products are all there and read back."""
    return (_json_ok(out / "report.json", "gcpfree.orient")
            and all(product_ok(out / p) for p in ORIENT_PRODUCTS.values()))


def pair_complete(out: str | Path) -> bool:
    """True when ``OUT/pair.json`` exists and every product it lists reads back with the
    size it had when the pair finished: a rerun skips this pair."""
    out = Path(out)
    try:
        manifest = json.loads((out / MANIFEST).read_text())
    except (OSError, ValueError):
        return False
    if not isinstance(manifest, dict) or manifest.get("format") != FORMAT:
        return False
    sizes = manifest.get("sizes", {})
    for rel in manifest.get("products", {}).values():
        path = out / rel
        if not product_ok(path) or sizes.get(rel) != path.stat().st_size:
            return False
    return True


# ------------------------------------------------------------------------------- steps


@task(name="evaluate-dsm", cache_policy=NO_CACHE)
def evaluate_dsm(params: PairParams, out: Path) -> Path:
    """The final DSM against the lidar (per class, LE68), with its mask and the GCPs."""
    from tasks.evaluation.lidar import EvaluationOptions, evaluate_lidar, write_evaluation

    options = EvaluationOptions(
        dem=out / "dsm.tif", lidar=Path(params.lidar), out=out / "eval.json",
        landcover=Path(params.landcover) if params.landcover else None,
        lidar_vertical=params.lidar_vertical, mask=out / "dsm_mask.tif",
        gcps=out / "gcps.json")
    report = evaluate_lidar(options)
    return write_evaluation(report, out / "eval.json")


def _reference_of(params: PairParams, out: Path) -> tuple[Path, str]:
    """The reference DEM the orientation used (given, or made from the SRTM tiles)."""
    if params.reference is not None:
        return Path(params.reference), params.reference_vertical
    return out / "relative" / "rel.reference.tif", "auto"


def make_orthos(params: PairParams, out: Path, skipped: list[str]) -> dict[str, str]:
    """Both images orthorectified with their oriented models over the reference DEM, on one
    grid (the left image's GSD, its UTM zone), then compared window by window."""
    import rasterio

    from core.ortho_compare import CompareConfig
    from tasks.ortho.orthorectify import OrthoConfig, orthorectify, plan_ortho
    from tasks.ortho.compare import compare_orthos, plan_compare
    from tasks.ortho.inputs import describe_dem
    from tasks.io.sensors import load_model

    dem_path, vertical = _reference_of(params, out)
    dem = describe_dem(dem_path, vertical)
    products: dict[str, str] = {}
    grid: tuple[float | None, int | None] = (None, None)
    for name, image in (("left", params.left), ("right", params.right)):
        path = out / f"ortho_{name}.tif"
        products[f"ortho_{name}"] = path.name
        if product_ok(path):
            skipped.append(f"ortho_{name}")
            with rasterio.open(path) as src:
                grid = (abs(src.transform.a), src.crs.to_epsg())
            continue
        loaded = load_model(Path(image), model=out / f"{name}.json", band=params.band)
        plan = plan_ortho(loaded, dem, *grid)
        grid = (plan.grid.res_m, plan.epsg)
        orthorectify(plan, path, OrthoConfig(), params.workers)
    cmp_json, cmp_map = out / "ortho_compare.json", out / "ortho_discrepancy.tif"
    products.update(ortho_compare=cmp_json.name, ortho_discrepancy=cmp_map.name)
    if product_ok(cmp_json) and product_ok(cmp_map):
        skipped.append("ortho_compare")
    else:
        with rasterio.open(out / "ortho_left.tif") as src:
            small = min(src.width, src.height) < 2000
        # a small ortho (a crop, coarse pixels) gets more, smaller windows, as many as fit
        cfg = CompareConfig(window_px=32, step_px=32) if small else CompareConfig()
        plan = plan_compare(out / "ortho_left.tif", out / "ortho_right.tif", cfg)
        compare_orthos(plan, cmp_json, cmp_map, out / "ortho_discrepancy.png", params.workers)
    return products


@task(name="write-stac", cache_policy=NO_CACHE, retries=1)
def write_stac(out: Path, pair_id: str, rasters: dict[str, Path]) -> Path:
    """The STAC catalog of the pair's rasters."""
    from tasks.archive.stac import RasterProduct, write_catalog

    titles = {"dsm": "final DSM, WGS84 ellipsoidal heights",
              "dsm_egm96": "final DSM, EGM96 orthometric heights",
              "dsm_mask": "final DSM mask (0 valid, 1 mismatch, 2 occluded/outside)",
              "relative_dem": "relative DEM (before absolute orientation)",
              "ortho_left": "left orthoimage", "ortho_right": "right orthoimage",
              "ortho_discrepancy": "left-right ortho discrepancy (px)"}
    products = [RasterProduct(k, p, titles.get(k, k),
                              ("data",) if k.startswith(("dsm", "ortho")) else ("metadata",))
                for k, p in rasters.items()]
    return write_catalog(out, pair_id, products, f"gcpfree products of pair {pair_id}",
                         properties={"gcpfree:pair": pair_id})


def _publish_artifacts(out: Path, pair_id: str) -> None:
    """Prefect artifacts: the orientation table, the LE68 table, a link to the report."""
    from prefect.artifacts import create_link_artifact, create_table_artifact

    key = "".join(c if c.isalnum() else "-" for c in pair_id.lower()).strip("-") or "pair"
    report = json.loads((out / "report.json").read_text())
    rows = []
    for name, a in report["absolute"]["images"].items():
        cp = report.get("check_points", {}).get(name, {})
        rows.append({"image": name, "gcp_rms_col_px": round(a["rms_col_px"], 3),
                     "gcp_rms_row_px": round(a["rms_row_px"], 3),
                     "check_rms_col_px": round(cp["rms_col_px"], 3) if cp else None,
                     "check_rms_row_px": round(cp["rms_row_px"], 3) if cp else None,
                     "gcps_used": report["gcps"]["used"]})
    create_table_artifact(rows, key=f"{key}-orientation",
                          description=f"{pair_id}: orientation without GCP")
    if (out / "eval.json").exists():
        ev = json.loads((out / "eval.json").read_text())
        le = [{"class": name, "count": s["count"], "le68_m": round(s["le68"], 3),
               "nmad_m": round(s["nmad"], 3), "bias_m": round(s["mean"], 3)}
              for name, s in [*ev["classes"].items(), ("all", ev["all"])]]
        create_table_artifact(le, key=f"{key}-le68", description=f"{pair_id}: DSM vs lidar")
    for name in ("report.html", "report.md"):
        if (out / name).exists():
            create_link_artifact((out / name).resolve().as_uri(), link_text=name,
                                 key=f"{key}-report", description=f"{pair_id}: report")
            break


def _write_manifest(out: Path, params: PairParams, pair_id: str,
                    products: dict[str, str]) -> Path:
    from tasks.io.rasters import atomic_write_json, json_ready

    doc = {"format": FORMAT, "version": 1, "pair_id": pair_id,
           "params": json_ready({k: (str(v) if isinstance(v, Path) else v)
                                 for k, v in asdict(params).items()}),
           "products": products,
           "sizes": {rel: (out / rel).stat().st_size for rel in products.values()}}
    return atomic_write_json(out / MANIFEST, doc)


@flow(name="orient-pair", log_prints=True)
def orient_pair_flow(params: PairParams) -> PairOutcome:
    """Orientation -> evaluation -> report -> STAC -> manifest, each step skipped when its
    products already read back."""
    from prefect.artifacts import create_progress_artifact, update_progress_artifact

    from core.errors import InputError
    from flows.orient import OrientParams, orient_flow

    out = Path(params.out)
    if params.lidar is None and params.landcover is not None:
        raise InputError("--landcover without --lidar: the land cover only classifies the "
                         "lidar evaluation; give --lidar too")
    out.mkdir(parents=True, exist_ok=True)
    pair_id = params.pair_id or out.resolve().name
    steps = ["orient", "orthos", "evaluate", "report", "stac"]
    progress = create_progress_artifact(0.0, description=f"{pair_id}: steps done")
    skipped: list[str] = []

    def done(step: str) -> None:
        update_progress_artifact(progress, 100.0 * (steps.index(step) + 1) / len(steps))

    if orientation_done(out):
        skipped.append("orient")
        print(f"orientation kept      {out / 'report.json'} (reads back)")
    else:
        orient_flow(OrientParams(
            left=Path(params.left), right=Path(params.right), out=out,
            left_model=params.left_model, right_model=params.right_model, band=params.band,
            reference=params.reference, reference_vertical=params.reference_vertical,
            srtm_dir=params.srtm_dir, checkpoints=params.checkpoints,
            self_calibrate=params.self_calibrate, corrections=params.corrections,
            workers=params.workers, progress=params.progress, spacing_m=params.spacing_m,
            min_windows=params.min_windows, surface=params.surface or SurfaceMatchConfig()))
    done("orient")

    products = dict(ORIENT_PRODUCTS)
    if (out / "dsm_mask.tif").exists():
        products["dsm_mask"] = "dsm_mask.tif"
    products.update(make_orthos(params, out, skipped))
    done("orthos")

    if params.lidar is not None:
        if _json_ok(out / "eval.json"):
            skipped.append("evaluate")
        else:
            evaluate_dsm(params, out)
        products["evaluation"] = "eval.json"
    done("evaluate")

    from tasks.report.build import write_report

    write_report(out, reference=params.reference, checkpoints=params.checkpoints,
                 evaluation=out / "eval.json" if params.lidar is not None else None,
                 reference_vertical=params.reference_vertical, surface=params.surface)
    for name in ("report.html", "report.md"):
        if (out / name).exists():
            products[name.replace(".", "_")] = name
    done("report")

    rasters = {k: out / v for k, v in products.items() if v.endswith(".tif")}
    catalog = write_stac(out, pair_id, rasters)
    products["stac"] = str(catalog.relative_to(out))
    done("stac")

    _publish_artifacts(out, pair_id)
    path = _write_manifest(out, params, pair_id, products)
    outcome = PairOutcome(path, json.loads(path.read_text()), tuple(skipped))
    for line in outcome.lines():
        print(line)
    return outcome
