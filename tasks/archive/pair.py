"""The products of one pair run by ``gcpfree pair`` (``flows.pair``): which of them read back
(so that a rerun resumes), the manifest ``OUT/pair.json`` written last, the STAC catalog of the
rasters, the Prefect artifacts, the headline figures; and which pairs of an archive are done.

A product that exists and reads back (JSON that parses, the orientation's report.json as
:func:`tasks.absolute.report.read_report` reads it, a raster that opens with its size) is kept;
:func:`pair_complete` reads the manifest and checks every product it lists with its size.
Every product is written under a temporary name and renamed into place whole, so a run killed
mid-way leaves only temporary names behind (:func:`leftovers`), which the next run of the pair
removes before it resumes.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from prefect import task
from prefect.cache_policies import NO_CACHE

from core.errors import GcpFreeError, InputError
from tasks.io.products import EVALUATION_STATS, PAIR, PAIR_FORMAT, PairManifest
from tasks.io.rasters import read_json

FORMAT = PAIR_FORMAT
MANIFEST = "pair.json"

# the orientation's products: manifest key -> file in OUT
ORIENT_PRODUCTS = {"report": "report.json", "left_model": "left.json",
                   "right_model": "right.json", "gcps": "gcps.json", "dsm": "dsm.tif",
                   "dsm_egm96": "dsm_egm96.tif", "relative_dem": "relative_dem.tif"}
STAC_TITLES = {"dsm": "final DSM, WGS84 ellipsoidal heights",
               "dsm_egm96": "final DSM, EGM96 orthometric heights",
               "dsm_mask": "final DSM mask (0 valid, 1 mismatch, 2 occluded/outside)",
               "relative_dem": "relative DEM (before absolute orientation)",
               "ortho_left": "left orthoimage", "ortho_right": "right orthoimage",
               "ortho_discrepancy": "left-right ortho discrepancy (px)"}


# ----------------------------------------------------------------------------- validity


def _read_json(path: Path) -> Any:
    """The JSON document at ``path``; InputError when it is missing or not JSON."""
    return read_json(path, "product")


def json_ok(path: Path) -> bool:
    """True when ``path`` holds JSON."""
    try:
        _read_json(path)
    except InputError:
        return False
    return True


def _raster_ok(path: Path) -> bool:
    import rasterio

    from tasks.io.rasters import open_raster

    try:
        with open_raster(path, "product") as src:
            return src.width > 0 and src.height > 0 and src.crs is not None
    except (InputError, OSError, rasterio.errors.RasterioError):
        return False


def product_ok(path: Path) -> bool:
    """True when ``path`` exists and reads back (rasters open, JSON parses)."""
    path = Path(path)
    if not path.is_file():
        return False
    if path.suffix.lower() in (".tif", ".tiff"):
        return _raster_ok(path)
    if path.suffix.lower() == ".json":
        return json_ok(path)
    return path.stat().st_size > 0


def orientation_done(out: Path, settings: Mapping[str, Any] | None = None) -> bool:
    """The orientation's products are all there and read back (report.json as the
    orientation's report) and, with ``settings`` (:meth:`flows.orient.OrientParams.settings`),
    report.json records the same: an orientation made from other inputs or options is not
    done."""
    return orientation_changes(out, settings) == ()


def orientation_changes(out: Path,
                        settings: Mapping[str, Any] | None = None) -> tuple[str, ...] | None:
    """None when the orientation's products are not all there or do not read back; else the
    names of the ``settings`` whose value differs from what report.json records (every name
    when it records none, an older gcpfree's report; a setting it lacks is unchanged when it
    is unset now, null: an option added since, at its default), () when none differs."""
    from tasks.absolute.report import read_report

    try:
        report = read_report(Path(out) / ORIENT_PRODUCTS["report"])
    except GcpFreeError:
        return None
    if not all(product_ok(Path(out) / p) for p in ORIENT_PRODUCTS.values()):
        return None
    if settings is None:
        return ()
    return settings_changes(report.settings, settings)


def settings_changes(had: Mapping[str, Any] | None,
                     settings: Mapping[str, Any]) -> tuple[str, ...]:
    """The names of the ``settings`` whose value differs from what a report.json recorded
    (``had``, its ``settings``): every name when it records none (an older gcpfree's report);
    a setting it lacks is unchanged when it is unset now (null: an option added since, at its
    default)."""
    if not had:
        return tuple(settings)
    return tuple(k for k in settings if not _same(had.get(k), settings[k]))


def _same(had: Any, now: Any) -> bool:
    """A recorded value against today's: equal, or, for mappings (``absolute``, ``surface``),
    equal key by key where a key the record lacks is unchanged when it is unset now (null:
    an option added since, at its default)."""
    if isinstance(had, Mapping) and isinstance(now, Mapping):
        return all(_same(had.get(k), v) for k, v in now.items())
    return had == now


def param_changes(had: Mapping[str, Any], params: Mapping[str, Any],
                  defaults: Mapping[str, Any] | None = None) -> tuple[str, ...]:
    """The names of the manifest parameters ``params`` (:meth:`flows.pair.PairParams.to_dict`)
    whose value differs from what a manifest recorded (``had``), those that only change how a
    run goes (:data:`RUN_ONLY_PARAMS`) aside. A parameter the manifest lacks (an option added
    since) or records as null (``surface`` in an archive's manifest before the archive passed
    it) compares as its value in ``defaults`` (:func:`flows.pair.manifest_defaults`; None
    without)."""
    defaults = defaults or {}
    return tuple(k for k, v in params.items() if k not in RUN_ONLY_PARAMS and not _same(
        had[k] if had.get(k) is not None else defaults.get(k), v))


def pair_complete(out: str | Path, params: Mapping[str, Any] | None = None,
                  defaults: Mapping[str, Any] | None = None) -> bool:
    """True when ``OUT/pair.json`` exists and every product it lists reads back with the
    size it had when the pair finished: a rerun skips this pair. With ``params`` (the
    manifest's, :meth:`flows.pair.PairParams.to_dict`), a manifest that records its parameters
    (every one gcpfree writes) must record the same (:func:`param_changes`, with the
    parameters' ``defaults``)."""
    out = Path(out)
    try:
        manifest = PAIR.read(out / MANIFEST)
    except InputError:
        return False
    had = manifest.params
    if params is not None and had is not None and param_changes(had, params, defaults):
        return False
    for rel in manifest.products.values():
        path = out / rel
        if not product_ok(path) or manifest.sizes.get(rel) != path.stat().st_size:
            return False
    return True


# what the pair flow makes from the oriented models: made again whenever the orientation is
DOWNSTREAM = ("pair.json", "ortho_left.tif", "ortho_right.tif", "ortho_compare.json",
              "ortho_discrepancy.tif", "ortho_discrepancy.png", "eval.json")


def remove_downstream(out: str | Path) -> list[Path]:
    """Remove the products of :data:`DOWNSTREAM` found in the pair folder ``out`` (the
    manifest first, so that a pair stopped mid-way is never taken for complete); the paths
    removed."""
    gone = [p for p in (Path(out) / n for n in DOWNSTREAM) if p.is_file()]
    for p in gone:
        p.unlink()
    return gone


# the pair's parameters that change how a run goes, not its products
RUN_ONLY_PARAMS = ("out", "workers", "progress", "pair_id")


# what a writer killed mid-way leaves in a pair folder (never a product: each is renamed into
# place whole): the atomic writers' temporary files and folders (``.<name>.tmp*``,
# :mod:`tasks.io.rasters`), the dense matching's work folders (``.<dem>.work``, rebuilt by the
# step that uses them) and the STAC writer's folders (``_stac_tmp_*``, ``_stac_old``,
# :mod:`tasks.archive.stac`)
LEFTOVER_PATTERNS = (".*.tmp*", ".*.work", "_stac_tmp_*", "_stac_old")


def leftovers(out: str | Path) -> list[Path]:
    """The temporary files and folders an interrupted run left in the pair folder ``out``
    (:data:`LEFTOVER_PATTERNS`, at any depth; a folder's own content is not listed again),
    sorted."""
    out = Path(out)
    if not out.is_dir():
        return []
    found = sorted({p for pattern in LEFTOVER_PATTERNS for p in out.rglob(pattern)})
    return [p for p in found if not any(q in p.parents for q in found)]


def remove_leftovers(out: str | Path) -> list[Path]:
    """Remove what :func:`leftovers` lists (the run that wrote them is over: its worker died or
    it was interrupted); the paths removed. Only one run may work in a pair folder at a time."""
    import shutil

    gone = leftovers(out)
    for p in gone:
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)
    return gone


@task(name="find-complete-pairs", cache_policy=NO_CACHE)
def complete_pairs(params: Mapping[str, Mapping[str, Any]], root: Path,
                   defaults: Mapping[str, Any] | None = None) -> frozenset[str]:
    """The pair ids (keys of ``params``, each pair's manifest parameters) whose ``ROOT/<id>``
    already holds valid finished products made with those parameters (:func:`pair_complete`,
    with their ``defaults``)."""
    return frozenset(i for i, p in params.items()
                     if pair_complete(Path(root) / i, p, defaults))


def write_manifest(out: Path, pair_id: str, params: Mapping[str, Any],
                   products: Mapping[str, str]) -> Path:
    """``OUT/pair.json``: the run's parameters, its products and their sizes (written last)."""
    return PAIR.write(Path(out) / MANIFEST, PairManifest(
        pair_id=pair_id, params=dict(params), products=dict(products),
        sizes={rel: (Path(out) / rel).stat().st_size for rel in products.values()}))


# ----------------------------------------------------------------------------- products


@task(name="write-stac", cache_policy=NO_CACHE, retries=1)
def write_stac(out: Path, pair_id: str, rasters: Mapping[str, Path]) -> Path:
    """The STAC catalog of the pair's rasters (``OUT/stac/catalog.json``)."""
    from tasks.archive.stac import RasterProduct, write_catalog

    products = [RasterProduct(k, p, STAC_TITLES.get(k, k),
                              ("data",) if k.startswith(("dsm", "ortho")) else ("metadata",))
                for k, p in rasters.items()]
    return write_catalog(out, pair_id, products, f"gcpfree products of pair {pair_id}",
                         properties={"gcpfree:pair": pair_id})


def read_evaluation_stats(path: Path):  # -> dict[str, DzStats] | None
    """The statistics of an ``eval.json`` of ``gcpfree evaluate``, per class and ``all``
    (:class:`core.evaluation.DzStats`, as the evaluation report writes them), or None when
    it is missing or not one."""
    try:
        stats = EVALUATION_STATS.load(_read_json(path), str(path))
    except GcpFreeError:
        return None
    return {**stats.classes, "all": stats.all}


def publish_artifacts(out: Path, pair_id: str) -> None:
    """Prefect artifacts of a finished pair: the orientation table, the LE68 table, a link to
    the report."""
    from prefect.artifacts import create_link_artifact, create_table_artifact

    from tasks.absolute.report import read_report

    key = "".join(c if c.isalnum() else "-" for c in pair_id.lower()).strip("-") or "pair"
    report = read_report(out)
    rows = []
    for name, a in report.absolute.images.items():
        cp = (report.check_points or {}).get(name)
        rows.append({"image": name, "gcp_rms_col_px": round(a.rms_col_px, 3),
                     "gcp_rms_row_px": round(a.rms_row_px, 3),
                     "check_rms_col_px": round(cp.rms_col_px, 3) if cp else None,
                     "check_rms_row_px": round(cp.rms_row_px, 3) if cp else None,
                     "gcps_used": report.gcps.used})
    create_table_artifact(rows, key=f"{key}-orientation",
                          description=f"{pair_id}: orientation without GCP")
    stats = read_evaluation_stats(out / "eval.json")
    if stats is not None:
        le = [{"class": name, "count": s.count, "le68_m": round(s.le68_m, 3),
               "nmad_m": round(s.nmad_m, 3), "bias_m": round(s.mean_m, 3)}
              for name, s in stats.items()]
        create_table_artifact(le, key=f"{key}-le68", description=f"{pair_id}: DSM vs lidar")
    for name in ("report.html", "report.md"):
        if (out / name).exists():
            create_link_artifact((out / name).resolve().as_uri(), link_text=name,
                                 key=f"{key}-report", description=f"{pair_id}: report")
            break


def figure_lines(out: Path) -> list[str]:
    """The pair's headline figures, read back from its products (those missing are left out):
    the orientation's, the ortho discrepancy, the DSM against the lidar."""
    from tasks.absolute.report import read_report

    lines: list[str] = []
    try:
        lines += read_report(out).lines()
    except GcpFreeError:
        pass
    try:
        c = _read_json(out / "ortho_compare.json")["px"]
        lines.append(f"ortho discrepancy     median {c['median_norm']:.2f} px, "
                     f"95th percentile {c['p95_norm']:.2f} px (left vs right ortho)")
    except (GcpFreeError, KeyError, TypeError, ValueError):
        pass
    stats = read_evaluation_stats(out / "eval.json")
    if stats is not None:
        a = stats["all"]
        lines.append(f"DSM vs lidar          LE68 {a.le68_m:.2f} m, NMAD {a.nmad_m:.2f} m, "
                     f"bias {a.mean_m:+.2f} m ({a.count} points; per class in eval.json)")
    return lines
