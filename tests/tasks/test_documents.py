"""The products' JSON through tasks/io/documents.py: the files gcpfree wrote before the move
(``tests/data/products_v0_1/``, commit 161fa7a) read with today's code into the values they
hold, and written back byte for byte; the hand-written writers still in core agree; bad files
are refused in one line naming the document and the key; NaN goes as null and comes back.
(report.json written by today's orient: ``tests/tasks/test_report.py``.)"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from core.errors import InputError
from core.evaluation.evaluation import DzStats
from core.jsonio import json_ready, parse_json, to_json
from core.matching.surface import WindowStatus
from core.points import CheckPointSet, control_points_to_dict
from core.sensors.orbit import SampledAttitude
from core.sensors.pushbroom import PushbroomModel
from tasks.absolute.report import REPORT
from tasks.dense.dem import DemSummary
from tasks.io.documents import Document, adapter, plain
from tasks.io.model_files import model_document, read_model_document
from tasks.io.products import (
    CHECKPOINTS,
    EVALUATION,
    EVALUATION_STATS,
    GCPS,
    PAIR,
    SCENE,
    WINDOWS,
    EvaluationStats,
)
from tasks.io.schemas import DOCUMENTS, NOT_MOVED, product_schemas
from tasks.io.sensors import sun_to_dict

V01 = Path(__file__).resolve().parents[1] / "data" / "products_v0_1"
# file -> (its document, what follows the JSON text: eval.json ends with a newline)
WRITTEN = {"gcps.json": (GCPS, ""), "windows.json": (WINDOWS, ""),
           "checkpoints.json": (CHECKPOINTS, ""), "eval.json": (EVALUATION, "\n"),
           "pair.json": (PAIR, ""), "archive_pair.json": (PAIR, ""), "scene.json": (SCENE, ""),
           "scene_realistic.json": (SCENE, ""), "report.json": (REPORT, "")}
MODELS = ("delivered_left.json", "left.json", "truth_left_realistic.json")


def _raw(name: str) -> object:
    return json.loads((V01 / name).read_text())  # the standard library's reading, not ours


@pytest.mark.parametrize("name", list(WRITTEN))
def test_old_products_write_back_byte_for_byte(name: str):
    doc, end = WRITTEN[name]
    text = (V01 / name).read_text()
    assert to_json(doc.dump(doc.read(V01 / name)), indent=1) + end == text


@pytest.mark.parametrize("name", MODELS)
def test_old_model_files_write_back_byte_for_byte(name: str):
    text = (V01 / name).read_text()
    model, sun = read_model_document(parse_json(text, name), name)
    assert to_json(model_document(model, sun), indent=1) == text
    # the model's own writer, which orient still calls, writes the same
    assert to_json({**model.to_dict(), **sun_to_dict(sun)}, indent=1) == text


def test_old_gcps_and_windows_read_into_their_values():
    raw = _raw("gcps.json")
    gcps = GCPS.read(V01 / "gcps.json").points
    assert len(gcps) == len(raw["points"]) == 6
    for p, r in zip(gcps, raw["points"], strict=True):
        assert (p.id, p.lon_deg, p.lat_deg, p.h_m, p.sigma_xy_m, p.sigma_h_m, p.source) == (
            r["id"], r["lon_deg"], r["lat_deg"], r["h_m"], r["sigma_xy_m"], r["sigma_h_m"],
            r["source"])
        assert {n: (ip.col, ip.row) for n, ip in p.image_points.items()} == {
            n: (v["col"], v["row"]) for n, v in r["images"].items()}
        assert dict(p.provenance) == r["provenance"]
    # the core writer orient still calls writes what the document writes
    assert control_points_to_dict(gcps) == GCPS.dump(GCPS.read(V01 / "gcps.json"))
    raw = _raw("windows.json")
    w = WINDOWS.read(V01 / "windows.json")
    assert [x.tie_point for x in w.windows] == [r["tie_point"] for r in raw["windows"]]
    for x, r in zip(w.windows, raw["windows"], strict=True):
        m = x.match
        assert m.status is WindowStatus[r["status"]] and isinstance(m.n_cells, int)
        for key, v in r.items():
            if key not in ("tie_point", "status"):
                got = getattr(m, key)
                assert got == v or (v is None and math.isnan(got)), key
    refused = [x.match for x in w.windows if not x.match.ok]
    assert refused and all(math.isnan(m.shift_h_m) for m in refused)  # null read as NaN
    assert dict(w.counts) == raw["counts"] == {"OK": 6, "MASKED": 6}


def test_old_checkpoints_and_evaluation_read_into_their_values():
    raw = _raw("checkpoints.json")
    cps = CHECKPOINTS.read(V01 / "checkpoints.json")
    assert cps.images == ("left", "right") and isinstance(cps.images, tuple)
    for p, r in zip(cps.points, raw["points"], strict=True):
        assert (p.id, p.lon_deg, p.h_m, p.H_egm96_m, p.x_m, p.land_cover) == (
            r["id"], r["lon_deg"], r["h_m"], r["H_egm96_m"], r["x_m"], r["land_cover"])
        assert {n: (ip.col, ip.row) for n, ip in p.image_points.items()} == {
            n: (r[n]["col"], r[n]["row"]) for n in ("left", "right")}
    assert CheckPointSet.from_dict(raw) == cps and cps.to_dict() == CHECKPOINTS.dump(cps)
    raw = _raw("eval.json")
    ev = EVALUATION.read(V01 / "eval.json")
    for name, s in {**ev.classes, "all": ev.all}.items():
        r = raw["all"] if name == "all" else raw["classes"][name]
        assert s.count == r["count"] and s.method == r["method"]
        for k in DzStats.KEYS:
            v = getattr(s, f"{k}_m")
            assert v == r[k] or (r[k] is None and math.isnan(v)), (name, k)
        assert isinstance(s.le68_ci_m, tuple) and list(s.le68_ci_m) == r["le68_ci"]
    assert ev.dem.bounds == tuple(raw["dem"]["bounds"]) and isinstance(ev.dem.bounds, tuple)
    assert ev.landcover is not None and dict(ev.landcover.names) == {
        int(c): n for c, n in raw["landcover"]["names"].items()}
    assert ev.points.refused_pct == raw["points"]["refused_pct"]
    assert ev.stats_config.seed == raw["statistics"]["seed"]
    stats = EVALUATION_STATS.read(V01 / "eval.json")
    assert stats.all == ev.all and stats.classes == ev.classes


def test_old_pair_manifests_read_into_their_values():
    for name in ("pair.json", "archive_pair.json"):
        raw = _raw(name)
        m = PAIR.read(V01 / name)
        assert (m.format, m.version, m.pair_id) == (raw["format"], raw["version"],
                                                    raw["pair_id"])
        assert m.params == raw["params"] and m.products == raw["products"]
        assert m.sizes == raw["sizes"]


def test_an_old_scene_json_reads_into_its_values():
    from core.simulation.scene import SceneDef

    raw = _raw("scene.json")
    scene = SCENE.read(V01 / "scene.json")
    assert scene.dem_window.as_tuple() == tuple(raw["dem_window"])
    assert scene.centre.to_list() == raw["centre"] and scene.grid.to_list() == raw["grid"]
    assert scene.errors.centre_error_m == tuple(raw["errors"]["centre_error_m"])
    assert scene.image_names == ("left", "right") and scene.dsm_range_m == tuple(
        raw["dsm_range_m"])
    for name, inj in scene.injected.items():
        r = raw["injected"][name]
        assert inj.roll_bias_rad == r["roll_bias_rad"] and inj.jitter == tuple(r["jitter"])
        assert inj.distortion.k1 == r["distortion"]["k1"] and inj.realistic is None
    assert SceneDef.from_dict(raw) == scene  # the simulator's own reader agrees
    realistic = SCENE.read(V01 / "scene_realistic.json")
    assert realistic == SceneDef.from_dict(_raw("scene_realistic.json"))
    assert realistic.injected["left"].realistic is not None and realistic.errors.lens
    with pytest.raises(InputError, match="key 'grid' must be a list of 5 values"):
        SCENE.load(_broken("scene.json", ("grid",), [1.0, 2.0]))


def test_an_oriented_model_reads_with_its_sampled_attitude_and_sun():
    raw = _raw("left.json")
    model, sun = read_model_document(raw, "left.json")
    assert isinstance(model, PushbroomModel) and isinstance(model.attitude, SampledAttitude)
    np.testing.assert_array_equal(model.attitude.times_s, raw["attitude"]["times_s"])
    np.testing.assert_array_equal(model.orbit.positions_m, raw["orbit"]["positions_m"])
    assert model.orbit.velocity_frame == raw["orbit"]["velocity_frame"] == "inertial"
    assert sun == (raw["sun"]["azimuth_deg"], raw["sun"]["elevation_deg"])
    assert {n: model.corrections.value(n) for n in raw["corrections"]} == raw["corrections"]
    assert model.correction_centre == tuple(raw["correction_centre"])
    assert PushbroomModel.from_dict(raw).to_dict() == model.to_dict()


def test_an_old_report_json_reads_into_its_values():
    """The v0.1 report.json (before the frames, the predicted parts and the SAR keys) into
    its sections' values: core's own classes where the section is core's result; its DEM
    summaries as the DEM step writes them (dsm.json: the same record, byte for byte)."""
    from core.matching.relief import ReliefVerdict
    from core.orientation.checkpoints import CheckPointStats

    raw = _raw("report.json")
    r = REPORT.read(V01 / "report.json")
    assert r.relative == raw["relative"] and r.settings == raw["settings"]
    assert r.report == raw["report"] and r.sar is None
    relief = r.surface_matching.relief
    assert isinstance(relief, ReliefVerdict) and relief.enough and relief.reason is None
    assert relief.to_dict() == raw["surface_matching"]["relief"]
    left = r.absolute.images["left"]
    assert left.param_names == tuple(raw["absolute"]["images"]["left"]["param_names"])
    assert (left.n, left.rms_col_px) == (36, raw["absolute"]["images"]["left"]["rms_col_px"])
    assert r.absolute.frames is None and r.reference.registration_estimate is None
    lens = r.absolute.self_calibration
    assert lens is not None and not lens.applied and lens.wald_correlated_limit == 8.0
    cp = r.check_points["right"]
    assert isinstance(cp, CheckPointStats) and cp.to_dict() == raw["check_points"]["right"]
    assert cp.predicted_relative_rms_col_px is None
    assert r.check_points_before["left"].predicted_rms_col_px is None
    assert r.relative_dem.roi == (0, 0, 600, 600) and r.dsm.summary.n_disp_range == (48, 48)
    assert json_ready(r.relative_dem.to_dict()) == raw["relative_dem"]
    text = (V01 / "dsm.json").read_text()
    dsm = adapter(DemSummary).validate_python(_raw("dsm.json"))
    assert to_json(plain(dsm), indent=1) == text == to_json(dsm.to_dict(), indent=1)


def test_nan_is_written_as_null_and_read_back_as_nan():
    nan = math.nan
    s = DzStats(0, nan, nan, nan, nan, nan, nan, nan, nan, nan, nan, (nan, nan), 0.95, "exact",
                0.0)
    doc = {"format": "gcpfree.evaluation",
           **EVALUATION_STATS.dump(EvaluationStats(classes={"2": s}, all=s))}
    text = to_json(doc)
    assert "NaN" not in text and text.count("null") == 2 * 12
    back = EVALUATION_STATS.load(parse_json(text, "eval.json"))
    assert all(math.isnan(getattr(back.all, f"{k}_m")) for k in DzStats.KEYS)
    assert math.isnan(back.classes["2"].le68_ci_m[1]) and back.all.count == 0


def _broken(name: str, path: tuple, value: object) -> dict:
    d = _raw(name)
    parent = d
    for k in path[:-1]:
        parent = parent[k]
    parent[path[-1]] = value
    return d


@pytest.mark.parametrize(("doc", "name", "path", "value", "message"), [
    (GCPS, "gcps.json", ("points", 2, "sigma_xy_m"), "3",
     "key 'points.2.sigma_xy_m' must be a number, got '3'"),
    (GCPS, "gcps.json", ("points", 0, "images", "left"), [1, 2], "key 'points.0.images.left'"),
    (WINDOWS, "windows.json", ("windows", 1, "status"), "FINE",
     "key 'windows.1.status' must be one of"),
    (CHECKPOINTS, "checkpoints.json", ("points", 3, "right", "row"), None, None),
    (EVALUATION, "eval.json", ("format",), "gcpfree.other",
     "key 'format' is 'gcpfree.other', not 'gcpfree.evaluation'"),
    (EVALUATION, "eval.json", ("all", "count"), 1.5, "key 'all.count' must be an integer"),
    (PAIR, "pair.json", ("sizes", "dsm.tif"), "big", "key 'sizes.dsm.tif'"),
])
def test_a_bad_file_is_refused_in_one_line_naming_the_key(doc: Document, name: str, path: tuple,
                                                          value: object, message: str | None):
    d = _broken(name, path, value)
    if message is None:  # a null where a number was: read as NaN, as the writer means it
        assert math.isnan(doc.load(d).points[3].image_points["right"].row)
        return
    with pytest.raises(InputError) as err:
        doc.load(d)
    msg = str(err.value)
    assert msg.startswith(f"{doc.name}: ") and message in msg and "\n" not in msg, msg
    assert msg.endswith(doc.hint)


@pytest.mark.parametrize(("path", "value", "message"), [
    (("timing", "t0_s"), None, "key 'timing.t0_s' must be a finite number, got None"),
    (("attitude", "type"), "wobbly", "key 'attitude' must have 'type' among"),
    (("camera", "type"), "pinhole", "key 'camera' must have 'type' among"),
    (("corrections", "spin"), 1.0, "key 'corrections' must map names among"),
    (("image", "n_cols"), 599, "key 'image.n_cols' (599) differs from the camera's 600"),
    (("format",), "gcpfree.rpc", "key 'format' is 'gcpfree.rpc', not 'gcpfree.pushbroom'"),
    (("sun", "elevation_deg"), 95.0, "key 'sun' has azimuth 140.0 and elevation 95.0"),
])
def test_a_bad_model_file_is_refused_in_one_line_naming_the_key(path, value, message):
    d = _broken("left.json" if path[0] == "sun" else "delivered_left.json", path, value)
    with pytest.raises(InputError) as err:
        read_model_document(d, "m.json")
    msg = str(err.value)
    assert msg.startswith("m.json: pushbroom model: ") and message in msg, msg
    assert "\n" not in msg and msg.count("m.json") == 1


def test_the_schemas_list_every_product_and_the_keys_of_its_file():
    schemas = product_schemas()
    assert set(schemas) == set(DOCUMENTS) | set(NOT_MOVED) | {"summary.csv"}
    for name in ("gcps.json", "windows.json", "checkpoints.json", "eval.json", "pair.json",
                 "report.json"):
        keys = set(schemas[name]["properties"])
        assert set(_raw(name)) <= keys | {"heights", "image_coordinates"}, name
    top = set(_raw("delivered_left.json"))
    assert top <= set(schemas["model (gcpfree.pushbroom)"]["properties"])
    assert schemas["summary.csv"]["x-columns"] == (V01 / "summary.csv").read_text().split(
        "\n")[0].split(",")
    assert all("x-not-moved" in schemas[n] for n in NOT_MOVED)
    json.dumps(schemas)  # plain JSON


def test_a_changed_value_changes_the_file():
    """The write-back above is no identity on the text: a value changed in the typed object
    shows in the file."""
    cps = CHECKPOINTS.read(V01 / "checkpoints.json")
    moved = replace(cps, points=(replace(cps.points[0], h_m=cps.points[0].h_m + 1.0),
                                 *cps.points[1:]))
    out = CHECKPOINTS.dump(moved)
    assert out["points"][0]["h_m"] == _raw("checkpoints.json")["points"][0]["h_m"] + 1.0
