"""Flow ``pair`` (``gcpfree pair``): the whole chain for one stereo pair, either sensor family,
resumable.

orientation (``flows.orient``, steps 1-4: relative orientation, relative DEM, SRTM surface
matching, GCPs, absolute orientation, final DSM) -> an ortho of each image over the reference
-> ortho-vs-ortho check -> lidar evaluation (when lidar is given) -> report -> STAC catalog ->
``OUT/pair.json``, the manifest written last.

Each step checks its products before running (:mod:`tasks.archive.pair`): a product that
exists and reads back is kept, so a rerun of an interrupted pair resumes at the first missing
step.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import Any

from prefect import flow

from core.choices import VERTICAL_CHOICES, VerticalChoice
from core.errors import InputError
from flows.orient import OrientParams
from tasks.io.pair import PairInputs


@dataclass(frozen=True)
class PairParams:
    """One pair to process: its orientation (:class:`flows.orient.OrientParams`: the pair's
    inputs, a reference or SRTM tiles required, the output folder, the check points, the SAR
    scene and every orientation option; see ``gcpfree orient``) and what the chain adds.

    ``lidar`` (LAS/LAZ, its heights ``lidar_vertical``) and ``landcover`` (a class raster)
    drive the evaluation; without lidar the pair ends with the ortho check. ``pair_id`` names
    the STAC items (default: OUT's folder name). The orientation's own ``write_report`` is not
    used: the chain writes the report once, after the evaluation.
    """

    orient: OrientParams
    lidar: Path | None = None
    landcover: Path | None = None
    lidar_vertical: VerticalChoice = "auto"
    pair_id: str | None = None

    def __post_init__(self) -> None:
        if self.lidar_vertical not in VERTICAL_CHOICES:
            raise InputError(f"--lidar-vertical {self.lidar_vertical!r} unknown; use one of "
                             f"{', '.join(VERTICAL_CHOICES)}")

    @property
    def pair(self) -> PairInputs:
        """The pair's inputs (the orientation's)."""
        return self.orient.pair

    @property
    def out(self) -> Path:
        """The output folder (the orientation's)."""
        return Path(self.orient.out)

    def to_dict(self) -> dict[str, Any]:
        """The manifest's ``params``, flat as gcpfree has always written them: the pair's
        inputs, then every option by name (those of :mod:`flows.options`): the orientation's
        fields (``surface`` one object), the adjustment's ``reference_sigma_m`` and, under
        ``absolute``, its other settings, the chain's own; JSON values. Keys added since a
        manifest was written compare as their defaults (:func:`manifest_defaults`)."""
        from core.jsonio import json_ready

        orient = asdict(self.orient)
        for name in ("pair", "write_report"):
            del orient[name]
        absolute = orient.pop("absolute")
        sigma = absolute.pop("reference_sigma_m")
        mine = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "orient"}
        return json_ready({**self.pair.to_dict(), **orient, **mine, "reference_sigma_m": sigma,
                           "absolute": absolute})


def manifest_defaults() -> dict[str, Any]:
    """The manifest's ``params`` of a pair whose options are all at their defaults, its files
    and folder aside: what a manifest that lacks a parameter (an option added since it was
    written) or records it null (``surface`` before the archive passed it) was made with."""
    made = PairParams(OrientParams(PairInputs(Path("left"), Path("right")), Path("out")))
    return {k: v for k, v in made.to_dict().items() if k not in ("left", "right", "out")}


@dataclass(frozen=True, eq=False)
class PairOutcome:
    """What :func:`pair_flow` wrote: the manifest and the steps it skipped."""

    manifest_path: Path
    manifest: dict[str, Any]
    skipped: tuple[str, ...]

    def lines(self) -> list[str]:
        from tasks.archive.pair import figure_lines

        m = self.manifest
        out = [f"pair                  {m['pair_id']}: {self.manifest_path}"]
        if self.skipped:
            out.append(f"resumed               kept {', '.join(self.skipped)}")
        out += figure_lines(self.manifest_path.parent)
        out.append("products              " + ", ".join(m["products"].values()))
        return out


def _reference_of(params: PairParams, out: Path) -> tuple[Path, str]:
    """The reference DEM the orientation used (given, or made from the SRTM tiles)."""
    if params.pair.reference is not None:
        return params.pair.reference, params.pair.reference_vertical
    return out / "relative" / "rel.reference.tif", "auto"


def make_orthos(params: PairParams, out: Path, skipped: list[str]) -> dict[str, str]:
    """Both images orthorectified with their oriented models over the reference DEM, on one
    grid (the left image's GSD, its UTM zone), then compared window by window; the products
    that read back are kept (their names added to ``skipped``)."""
    from core.ortho.ortho_compare import CompareConfig
    from tasks.archive.pair import product_ok
    from tasks.io.rasters import open_raster
    from tasks.ortho.compare import compare_orthos, plan_compare
    from tasks.ortho.inputs import describe_dem
    from tasks.ortho.orthorectify import OrthoConfig, orthorectify, plan_ortho

    dem = describe_dem(*_reference_of(params, out))
    oriented = params.pair.with_models(out / "left.json", out / "right.json").load()
    products: dict[str, str] = {}
    grid: tuple[float | None, int | None] = (None, None)
    for name, loaded in zip(("left", "right"), oriented, strict=True):
        path = out / f"ortho_{name}.tif"
        products[f"ortho_{name}"] = path.name
        if product_ok(path):
            skipped.append(f"ortho_{name}")
            with open_raster(path, f"{name} ortho") as src:
                grid = (abs(src.transform.a), src.crs.to_epsg())
            continue
        plan = plan_ortho(loaded, dem, *grid)
        grid = (plan.grid.res_m, plan.epsg)
        orthorectify(plan, path, OrthoConfig(), params.orient.workers)
    cmp_json, cmp_map = out / "ortho_compare.json", out / "ortho_discrepancy.tif"
    products.update(ortho_compare=cmp_json.name, ortho_discrepancy=cmp_map.name)
    if product_ok(cmp_json) and product_ok(cmp_map):
        skipped.append("ortho_compare")
    else:
        with open_raster(out / "ortho_left.tif", "left ortho") as src:
            small = min(src.width, src.height) < 2000
        # a small ortho (a crop, coarse pixels) gets more, smaller windows, as many as fit
        cfg = CompareConfig(window_px=32, step_px=32) if small else CompareConfig()
        plan = plan_compare(out / "ortho_left.tif", out / "ortho_right.tif", cfg)
        compare_orthos(plan, cmp_json, cmp_map, out / "ortho_discrepancy.png",
                       params.orient.workers)
    return products


@flow(name="pair", log_prints=True)
def pair_flow(params: PairParams) -> PairOutcome:
    """Orientation -> orthos -> evaluation -> report -> STAC -> manifest, each step skipped
    when its products already read back."""
    from prefect.artifacts import create_progress_artifact, update_progress_artifact

    from flows.orient import orient_flow
    from tasks.archive.pair import (
        ORIENT_PRODUCTS,
        json_ok,
        orientation_changes,
        publish_artifacts,
        remove_downstream,
        write_manifest,
        write_stac,
    )
    from tasks.evaluation.lidar import EvaluationOptions, evaluate_lidar, write_evaluation
    from tasks.io.rasters import read_json
    from tasks.report.build import write_report

    out, pair = Path(params.out), params.pair
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

    orient = replace(params.orient, out=out, write_report=False)  # the report: once, below
    changes = orientation_changes(out, orient.settings())
    if changes == ():
        skipped.append("orient")
        print(f"orientation kept      {out / 'report.json'} (reads back, same settings)")
    else:
        if changes:
            print(f"orientation redone    {out / 'report.json'} was made with other settings: "
                  f"{', '.join(changes)}")
        # what an earlier orientation's models made (orthos, evaluation, manifest) goes first,
        # so that a run stopped before making them again never resumes on stale products
        gone = remove_downstream(out)
        if gone:
            print(f"removed               {', '.join(p.name for p in gone)} (made with the "
                  "earlier orientation)")
        orient_flow(orient)
    done("orient")

    products = dict(ORIENT_PRODUCTS)
    if (out / "dsm_mask.tif").exists():
        products["dsm_mask"] = "dsm_mask.tif"
    products.update(make_orthos(params, out, skipped))
    done("orthos")

    if params.lidar is not None:
        if json_ok(out / "eval.json"):
            skipped.append("evaluate")
        else:  # the final DSM against the lidar, with its mask and the GCPs
            write_evaluation(evaluate_lidar(EvaluationOptions(
                dem=out / "dsm.tif", lidar=Path(params.lidar), out=out / "eval.json",
                landcover=Path(params.landcover) if params.landcover else None,
                lidar_vertical=params.lidar_vertical, mask=out / "dsm_mask.tif",
                gcps=out / "gcps.json")), out / "eval.json")
        products["evaluation"] = "eval.json"
    done("evaluate")

    write_report(out, reference=pair.reference, checkpoints=orient.checkpoints,
                 evaluation=out / "eval.json" if params.lidar is not None else None,
                 reference_vertical=pair.reference_vertical, surface=orient.surface)
    for name in ("report.html", "report.md"):
        if (out / name).exists():
            products[name.replace(".", "_")] = name
    done("report")

    rasters = {k: out / v for k, v in products.items() if v.endswith(".tif")}
    catalog = write_stac(out, pair_id, rasters)
    products["stac"] = str(catalog.relative_to(out))
    done("stac")

    publish_artifacts(out, pair_id)
    path = write_manifest(out, pair_id, params.to_dict(), products)
    outcome = PairOutcome(path, read_json(path, "manifest"), tuple(skipped))
    for line in outcome.lines():
        print(line)
    return outcome
