"""A pair's options by name (:mod:`flows.options`): products written before the parameters were
nested compare equal to today's for the same options, so an existing archive is not rerun
(the fixtures of ``tests/data/products_v0_1``, written by commit 161fa7a); every option of the
dataclasses reads back and reaches the manifest; a catalog (CSV, JSON) and the archive's
command line pass any of them, a pair's own winning; the string options are typed and refused
in one line."""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import pytest

from core.errors import InputError
from core.jsonio import json_ready
from flows.commands import archive as archive_command
from flows.commands import pair as pair_command
from flows.options import OPTIONS, given_options, parse_option, with_options
from flows.orient import OrientParams
from flows.pair import PairParams, manifest_defaults
from flows.reprocess_archive import pair_params
from tasks.archive.catalog import PairEntry, read_catalog
from tasks.archive.pair import param_changes, settings_changes
from tasks.io.pair import PairInputs

REPO = Path(__file__).resolve().parents[2]
OLD = REPO / "tests" / "data" / "products_v0_1"
# where those products were made (tests/data/README.md): the scene, the pair, the archive
SCENE, CAT = "/tmp/ser/scene", "/tmp/ser/cat/p1"


def parse(command, *argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="gcpfree")
    command.add_parser(parser.add_subparsers(dest="command"))
    return parser.parse_args([command.__name__.rsplit(".", 1)[-1], *argv])


def pair_command_params(monkeypatch, *extra: str) -> PairParams:
    """What ``gcpfree pair`` runs with the options the fixtures' pair was made with
    (README: --checkpoints, --lidar, --landcover, --self-calibrate), ``extra`` added; the
    files are not read (they were on the machine that made them)."""
    import flows.commands._pair
    import tasks.absolute.orientation
    from flows.commands._pair import orientation_params

    monkeypatch.setattr(tasks.absolute.orientation, "read_checkpoints", lambda path: None)
    monkeypatch.setattr(flows.commands._pair, "_check_scene_size", lambda *a: None)
    args = parse(pair_command, "--left", f"{SCENE}/left.tif", "--right", f"{SCENE}/right.tif",
                 "--reference", f"{SCENE}/reference.tif", "--checkpoints",
                 f"{SCENE}/truth/checkpoints.json", "--lidar", f"{SCENE}/truth/lidar.laz",
                 "--landcover", f"{SCENE}/truth/landcover.tif", "--self-calibrate", *extra,
                 "--out", "/tmp/ser/pair")
    orient = orientation_params(args, "pair", (PairInputs.from_args(args), None, None))
    return PairParams(orient, lidar=args.lidar, landcover=args.landcover,
                      lidar_vertical=args.lidar_vertical, pair_id=args.pair_id)


def old(name: str, key: str) -> dict:
    return json.loads((OLD / name).read_text())[key]


def test_products_written_before_the_nesting_compare_equal(monkeypatch):
    """pair.json's params and report.json's settings written by ``gcpfree pair`` at 161fa7a
    (flat PairParams) against the nested parameters the same command line makes today: no
    change, so neither the pair nor its orientation is redone; one option changed is seen,
    by its name."""
    params = pair_command_params(monkeypatch)
    defaults = manifest_defaults()
    assert param_changes(old("pair.json", "params"), params.to_dict(), defaults) == ()
    assert settings_changes(old("report.json", "settings"), params.orient.settings()) == ()
    changed = pair_command_params(monkeypatch, "--corrections", "offset", "--max-shift", "25")
    assert param_changes(old("pair.json", "params"), changed.to_dict(), defaults) == (
        "corrections", "surface")
    assert settings_changes(old("report.json", "settings"), changed.orient.settings()) == (
        "corrections", "surface")


def test_an_archive_pair_written_before_the_nesting_is_complete():
    """archive_pair.json (``gcpfree archive`` at 161fa7a: ``surface`` null, no ``absolute``,
    ``sar_sigma_m`` nor ``geoid``) against the parameters the archive makes today for that
    catalog entry: equal through the defaults, unequal without them (what the defaults are
    for) and unequal for another option."""
    entry = PairEntry("p1", Path(f"{CAT}/left.tif"), Path(f"{CAT}/right.tif"),
                      lidar=Path(f"{CAT}/lidar.laz"), landcover=Path(f"{CAT}/landcover.tif"),
                      checkpoints=Path(f"{CAT}/checkpoints.json"))
    had = old("archive_pair.json", "params")
    now = pair_params(entry, Path("/tmp/ser/arch"), None, Path(f"{SCENE}/reference.tif"))
    assert param_changes(had, now.to_dict(), manifest_defaults()) == ()
    assert param_changes(had, now.to_dict()) == ("surface", "absolute")
    calibrated = pair_params(entry, Path("/tmp/ser/arch"), None,
                             Path(f"{SCENE}/reference.tif"), options={"self_calibrate": True})
    assert param_changes(had, calibrated.to_dict(), manifest_defaults()) == ("self_calibrate",)


DEFAULT = PairParams(OrientParams(PairInputs(Path("l.tif"), Path("r.tif")), Path("out")))


@pytest.mark.parametrize("name", sorted(OPTIONS))
def test_every_option_reads_back_from_json_and_reaches_the_manifest(name):
    option = OPTIONS[name]
    assert parse_option(name, json.loads(json.dumps(json_ready(option.default)))) \
        == option.default
    assert with_options(DEFAULT, {name: option.default}) == DEFAULT
    manifest = DEFAULT.to_dict()
    config, _, field = name.rpartition(".")
    assert field in (manifest[config] if config else manifest), name


def test_options_are_read_with_their_types():
    assert parse_option("self_calibrate", "yes") is True
    assert parse_option("reference_sigma_m", "1 2.5 0") == (1.0, 2.5, 0.0)
    assert parse_option("absolute.prior_terms", ["k1", "p1"]) == ("k1", "p1")
    assert parse_option("surface.detrend", "2") == 2
    assert parse_option("surface.detrend", "false") is False
    assert parse_option("spacing_m", "") is None and parse_option("band", "3") == 3
    for name, value, says in [
            ("corrections", "affine", "option corrections 'affine': use one of linear, offset"),
            ("min_windows", "2.5", "option min_windows '2.5': give a whole number"),
            ("spacing_m", "nan", "option spacing_m 'nan': give a finite number"),
            ("reference_sigma_m", "1 2", "option reference_sigma_m '1 2': give 3 values"),
            ("self_calibrate", "maybe", "option self_calibrate 'maybe': give true or false"),
            ("self_calibration", "true",
             "unknown option 'self_calibration'; did you mean self_calibrate?")]:
        with pytest.raises(InputError, match="^pair p: " + says.replace("?", r"\?")):
            parse_option(name, value, "pair p")


@pytest.mark.parametrize(("make", "says"), [
    (lambda: OrientParams(PairInputs("l", "r"), Path("o"),
                          corrections="affine"),  # type: ignore[arg-type]
     "--corrections 'affine' unknown; use one of linear, offset"),
    (lambda: OrientParams(PairInputs("l", "r"), Path("o"), min_windows=0),
     "--min-windows must be at least 1"),
    (lambda: PairParams(DEFAULT.orient, lidar_vertical="msl"),  # type: ignore[arg-type]
     "--lidar-vertical 'msl' unknown; use one of auto, ellipsoidal, egm96"),
    (lambda: PairInputs("l", "r", tie_measure="sad"),  # type: ignore[arg-type]
     "--tie-measure 'sad' unknown; use one of auto, ncc, orientation"),
])
def test_string_options_are_refused_in_one_line(make, says):
    with pytest.raises(InputError, match=says) as err:
        make()
    assert "\n" not in str(err.value)


CSV = """id,left,right,self_calibrate,corrections,surface.radius_m,reference_sigma_m
a,a/l.tif,a/r.tif,true,offset,3000,2 2 4
b,b/l.tif,b/r.tif,,,,
"""


def test_a_catalog_passes_any_option_per_pair_over_the_archives(tmp_path):
    (tmp_path / "cat.csv").write_text(CSV)
    (tmp_path / "cat.json").write_text(json.dumps([
        {"id": "a", "left": "a/l.tif", "right": "a/r.tif", "self_calibrate": True,
         "corrections": "offset", "surface.radius_m": 3000, "reference_sigma_m": [2, 2, 4]},
        {"id": "b", "left": "b/l.tif", "right": "b/r.tif", "corrections": None}]))
    archive = {"corrections": "linear", "min_windows": 12}  # the command line's, every pair
    for name in ("cat.csv", "cat.json"):
        a, b = read_catalog(tmp_path / name, tuple(OPTIONS)).pairs
        pa, pb = (pair_params(e, tmp_path / "root", None, tmp_path / "ref.tif", "auto",
                              archive) for e in (a, b))
        assert pa.orient == replace(
            pb.orient, pair=pa.pair, out=pa.out, self_calibrate=True, corrections="offset",
            surface=replace(pb.orient.surface, radius_m=3000.0),
            absolute=replace(pb.orient.absolute, reference_sigma_m=(2.0, 2.0, 4.0))), name
        assert (pb.orient.corrections, pb.orient.min_windows) == ("linear", 12)  # not given
        assert pa.orient.min_windows == 12
        manifest = pa.to_dict()
        assert (manifest["self_calibrate"], manifest["surface"]["radius_m"],
                manifest["reference_sigma_m"]) == (True, 3000.0, [2.0, 2.0, 4.0])
    with pytest.raises(InputError, match=r"unknown column\(s\) self_calibration; did you mean "
                                         "self_calibrate"):
        (tmp_path / "typo.csv").write_text("id,left,right,self_calibration\np,l,r,true\n")
        read_catalog(tmp_path / "typo.csv", tuple(OPTIONS))
    with pytest.raises(InputError, match=r"unknown column\(s\) self_calibrate"):
        read_catalog(tmp_path / "cat.csv")  # a reader given no options takes none
    (tmp_path / "bad.csv").write_text("id,left,right,surface.radius_m\np,l,r,-5\n")
    entry, = read_catalog(tmp_path / "bad.csv", tuple(OPTIONS)).pairs
    with pytest.raises(InputError, match="^pair p of the catalog: surface matching needs a "
                                         "window radius > 0 m"):
        pair_params(entry, tmp_path, None, tmp_path / "ref.tif")


def test_the_archive_command_line_gives_every_pair_its_options(tmp_path):
    (tmp_path / "cat.csv").write_text("id,left,right\np,l.tif,r.tif\n")
    base = ("--catalog", str(tmp_path / "cat.csv"), "--out", str(tmp_path / "o"),
            "--srtm-dir", str(tmp_path))
    args = parse(archive_command, *base, "--no-along-track", "--corrections", "offset",
                 "--window-spacing", "2500", "--tie-measure", "ncc", "--lidar-vertical",
                 "egm96", "--reference-sigma", "5", "5", "5")  # the last at its default
    assert given_options(args) == {"along_track": False, "corrections": "offset",
                                   "spacing_m": 2500.0, "tie_measure": "ncc",
                                   "lidar_vertical": "egm96"}
    assert archive_command.flow_parameters(args)["options"] == given_options(args)
    assert given_options(parse(archive_command, *base)) == {}
    with pytest.raises(InputError, match="surface matching needs a window radius > 0 m"):
        archive_command.check_archive_args(parse(archive_command, *base, "--window-radius",
                                                 "-5"))


def test_the_archive_page_lists_every_option():
    """The catalog's columns are documented (docs/reference/notes/archive.md): an option
    added to the dataclasses without a line there fails."""
    text = (REPO / "docs" / "reference" / "notes" / "archive.md").read_text()
    missing = [n for n in OPTIONS if f"`{n}`" not in text]
    assert not missing, missing


def test_an_option_added_inside_a_nested_setting_is_unchanged_only_while_unset():
    """``absolute.components_by_frame`` came after products that record ``absolute`` without
    it: unset now (null), they are kept; set, the orientation is redone, by that setting's
    name; a recorded value that differs is a change as before."""
    had = {"absolute": {"huber_k": 1.5}, "surface": {"radius": 4000.0}}
    now = {"absolute": {"huber_k": 1.5, "components_by_frame": None},
           "surface": {"radius": 4000.0}}
    assert settings_changes(had, now) == ()
    assert param_changes(had, now) == ()
    on = {**now, "absolute": {"huber_k": 1.5, "components_by_frame": True}}
    assert settings_changes(had, on) == ("absolute",)
    assert param_changes(had, on) == ("absolute",)
    other = {**now, "absolute": {"huber_k": 2.0, "components_by_frame": None}}
    assert settings_changes(had, other) == ("absolute",)
