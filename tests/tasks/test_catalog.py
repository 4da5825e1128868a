"""The archive's catalog (a folder of pair folders, CSV, JSON) and its summary files."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from core.errors import GcpFreeError, InputError
from tasks.archive.catalog import (
    FIELDS,
    Catalog,
    PairEntry,
    PairRow,
    _transient,
    check_pair_inputs,
    pair_row,
    read_catalog,
    summary_csv,
    write_summary,
)
from tests.flows.reports import finished_evaluation, finished_report


def touch(path: Path, text: str = "x") -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def test_directory_of_pair_folders(tmp_path: Path):
    cat = tmp_path / "archive"
    # the simulator's layout: images at the top, truth/ with lidar and check points
    a = cat / "a_2020"
    touch(a / "left.tif"), touch(a / "right.tif"), touch(a / "left.json")
    touch(a / "truth" / "lidar.laz"), touch(a / "truth" / "checkpoints.json")
    touch(a / "truth" / "landcover.tif")
    touch(a / "sar.tif"), touch(a / "sar.xml")  # a SAR scene of the same ground
    # SPOT products in left/ and right/ folders; files in the pair folder win over truth/
    b, c = cat / "b", cat / "c"
    touch(b / "left" / "IMAGERY.TIF"), touch(b / "left" / "METADATA.DIM")
    touch(b / "left" / "PREVIEW.JPG")
    touch(b / "right" / "IMAGERY.TIF"), touch(b / "right" / "METADATA.DIM")
    touch(b / "right" / "ICON.tif")
    touch(b / "landcover.tif"), touch(b / "truth" / "landcover.tif")
    touch(b / "checkpoints.csv"), touch(b / "lidar.las")
    # a land cover without lidar is of no use (it classifies the lidar evaluation)
    touch(c / "landcover.tif")
    # a folder with one image each side under another name
    touch(c / "left" / "scene_1.tif"), touch(c / "right" / "scene_2.jp2")
    # ignored: hidden folders, underscore folders, loose files
    touch(cat / ".cache" / "left.tif"), touch(cat / "_trash" / "x"), touch(cat / "notes.txt")

    got = read_catalog(cat)
    assert got == Catalog(cat, (
        PairEntry("a_2020", a / "left.tif", a / "right.tif", lidar=a / "truth" / "lidar.laz",
                  landcover=a / "truth" / "landcover.tif",
                  checkpoints=a / "truth" / "checkpoints.json", sar=a / "sar.tif"),
        PairEntry("b", b / "left" / "IMAGERY.TIF", b / "right" / "IMAGERY.TIF",
                  lidar=b / "lidar.las", landcover=b / "landcover.tif",
                  checkpoints=b / "checkpoints.csv"),
        PairEntry("c", c / "left" / "scene_1.tif", c / "right" / "scene_2.jp2"),
    ))
    assert got.ids == ("a_2020", "b", "c")
    for entry in got.pairs:
        check_pair_inputs(entry)  # every file there


def test_pair_folder_without_images_fails_alone_with_its_reason(tmp_path: Path):
    cat = tmp_path / "archive"
    touch(cat / "good" / "left.tif"), touch(cat / "good" / "right.tif")
    touch(cat / "empty" / "readme.txt")
    touch(cat / "two" / "left" / "a.tif"), touch(cat / "two" / "left" / "b.tif")
    touch(cat / "two" / "right.tif")
    got = {p.id: p for p in read_catalog(cat).pairs}
    assert got["empty"].left == cat / "empty" / "left.tif"  # where it was expected
    with pytest.raises(InputError, match=r"^left image .*empty/left.tif does not exist; "
                                         r"a pair folder holds left.tif"):
        check_pair_inputs(got["empty"])
    with pytest.raises(InputError, match="^left image .*two/left.tif does not exist"):  # ambiguous: two images
        check_pair_inputs(got["two"])
    check_pair_inputs(got["good"])


CSV_TEXT = """id,left,right,left_model,lidar,sar,sar_model
p1,imgs/l1.tif,imgs/r1.tif,,,s1/m.tiff,s1/a.xml
p2 , {abs}/l2.tif , imgs/r2.tif , models/l2.DIM , p2.laz,,

"""


def test_csv_and_json_lists(tmp_path: Path):
    (tmp_path / "cat.csv").write_text(CSV_TEXT.format(abs="/data"))
    rows = [{"id": "p1", "left": "imgs/l1.tif", "right": "imgs/r1.tif", "sar": "s1/m.tiff",
             "sar_model": "s1/a.xml"},
            {"id": "p2", "left": "/data/l2.tif", "right": "imgs/r2.tif",
             "left_model": "models/l2.DIM", "lidar": "p2.laz", "checkpoints": None}]
    (tmp_path / "cat.json").write_text(json.dumps(rows))
    (tmp_path / "wrapped.json").write_text(json.dumps({"pairs": rows}))
    expected = (
        PairEntry("p1", tmp_path / "imgs/l1.tif", tmp_path / "imgs/r1.tif",
                  sar=tmp_path / "s1/m.tiff", sar_model=tmp_path / "s1/a.xml"),
        PairEntry("p2", Path("/data/l2.tif"), tmp_path / "imgs/r2.tif",
                  left_model=tmp_path / "models/l2.DIM", lidar=tmp_path / "p2.laz"),
    )
    for name in ("cat.csv", "cat.json", "wrapped.json"):
        assert read_catalog(tmp_path / name).pairs == expected, name
    with pytest.raises(InputError, match="lidar .*p2.laz of pair p2 does not exist"):
        touch(tmp_path / "imgs" / "r2.tif")
        touch(Path(tmp_path / "models" / "l2.DIM"))
        check_pair_inputs(PairEntry("p2", tmp_path / "imgs/r2.tif", tmp_path / "imgs/r2.tif",
                                    lidar=tmp_path / "p2.laz"))


BAD = [
    ("missing.csv", None, "does not exist; give a folder of pair folders"),
    ("cat.txt", "id,left,right\n", "unknown kind"),
    ("cat.csv", "", "is empty; its first line is the header"),
    ("cat.csv", "id,left\np,l.tif\n", "missing column.* right"),
    ("cat.csv", "id,left,right,cloud\np,l,r,1\n", "unknown column.* cloud"),
    ("cat.csv", "id,left,right\n,l.tif,r.tif\n", "line 2: id is empty"),
    ("cat.csv", "id,left,right\np,l.tif,\n", "line 2: right is empty"),
    ("cat.csv", "id,left,right\np,l,r\np,l2,r2\n", "pair id 'p' appears twice"),
    ("cat.csv", "id,left,right\n../up,l,r\n", "pair id '../up' is not a folder name"),
    ("cat.csv", "id,left,right\np,l,r,extra\n", "line 2: more values than"),
    ("cat.csv", "id,left,right\n", "lists no pair"),
    ("cat.csv", b"id,left,right\np,\xff\xfe,r\n", "is not UTF-8 text"),
    ("cat.json", "[{\"id\": \"p\",", "is not valid JSON"),
    ("cat.json", "{\"id\": \"p\"}", "expected a JSON list of pairs"),
    ("cat.json", "[\"p\"]", "pair 0 is a str, not an object"),
    ("cat.json", "[{\"id\": 3, \"left\": \"l\", \"right\": \"r\"}]", "id must be a string"),
    ("cat.json", "[]", "lists no pair"),
    ("cat.json", "[{\"id\": \"p\", \"left\": \"l\"}]", "missing column.* right"),
    ("empty_dir", "DIR", "lists no pair; add pair folders"),
]


@pytest.mark.parametrize(("name", "content", "message"), BAD)
def test_bad_catalogs_are_refused_in_one_line(tmp_path: Path, name, content, message):
    path = tmp_path / name
    if content == "DIR":
        path.mkdir()
    elif isinstance(content, bytes):
        path.write_bytes(content)
    elif content is not None:
        path.write_text(content)
    with pytest.raises(InputError, match=message) as err:
        read_catalog(path)
    assert "\n" not in str(err.value)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.binary(max_size=200), suffix=st.sampled_from([".csv", ".json"]))
def test_garbage_is_a_catalog_or_one_clear_error(tmp_path_factory, data: bytes, suffix: str):
    path = tmp_path_factory.mktemp("garbage") / f"cat{suffix}"
    path.write_bytes(data)
    try:
        cat = read_catalog(path)
    except InputError as exc:
        assert "\n" not in str(exc)
    else:
        assert cat.pairs and all(isinstance(p, PairEntry) for p in cat.pairs)


def test_catalog_reading_retries_io_errors_only():
    from prefect.states import Failed

    assert _transient(None, None, Failed(data=OSError("stale NFS handle")))
    assert not _transient(None, None, Failed(data=InputError("bad catalog")))
    assert issubclass(InputError, GcpFreeError)


def _report(tmp: Path) -> None:
    touch(tmp / "report.json", json.dumps(finished_report(
        37, {"left": (0.31, 0.42), "right": (0.5, 0.25)},
        {"left": (0.61, 0.72), "right": (0.83, 0.94)})))
    touch(tmp / "eval.json", json.dumps(finished_evaluation(4.25)))


def test_pair_row_reads_the_products(tmp_path: Path):
    _report(tmp_path)
    row = pair_row("p", "done", tmp_path)
    assert row == PairRow(
        id="p", status="done", gcps=37, cp_left_rms_col_px=0.61, cp_left_rms_row_px=0.72,
        cp_right_rms_col_px=0.83, cp_right_rms_row_px=0.94, gcp_left_rms_col_px=0.31,
        gcp_left_rms_row_px=0.42, gcp_right_rms_col_px=0.5, gcp_right_rms_row_px=0.25,
        le68_m=4.25, out=str(tmp_path))
    # no check points, no lidar: unknown, not zero
    touch(tmp_path / "report.json", json.dumps(finished_report(9, {"left": (0.3, 0.4)})))
    (tmp_path / "eval.json").unlink()
    row = pair_row("p", "skipped", tmp_path)
    assert row.gcps == 9 and row.cp_left_rms_col_px is None and row.le68_m is None
    assert row.gcp_left_rms_row_px == 0.4 and row.gcp_right_rms_col_px is None
    # a report.json that is not the orientation's (an older hand-made one, a damaged file):
    # no figure rather than a wrong one
    for text in (json.dumps({"format": "gcpfree.orient", "gcps": {"used": 9}}), "{ trunc"):
        touch(tmp_path / "report.json", text)
        assert pair_row("p", "done", tmp_path).gcps is None
    # a failed pair gives only its reason (first line), whatever lies in its folder
    row = pair_row("p", "failed", tmp_path, "InputError: bad\n  traceback...")
    assert row.reason == "InputError: bad" and row.gcps is None
    with pytest.raises(ValueError, match="status"):
        PairRow("p", "lost")


def test_summary_files_round_trip(tmp_path: Path):
    _report(tmp_path / "a")
    rows = (pair_row("a", "done", tmp_path / "a"),
            pair_row("b", "refused", tmp_path / "b", "too flat, 3 windows of 8 needed"),
            pair_row("c, \"quoted\"", "skipped", tmp_path / "c"))
    csv_path, json_path = write_summary.fn(rows, tmp_path, tmp_path / "cat.csv")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "summary.csv", "summary.json"]
    with csv_path.open(newline="") as f:
        back = list(csv.DictReader(f))
    assert tuple(back[0]) == FIELDS
    assert [r["id"] for r in back] == ["a", "b", "c, \"quoted\""]
    assert [r["status"] for r in back] == ["done", "refused", "skipped"]
    assert back[1]["reason"] == "too flat, 3 windows of 8 needed"
    assert float(back[0]["cp_right_rms_row_px"]) == 0.94 and back[0]["gcps"] == "37"
    assert float(back[0]["le68_m"]) == 4.25 and back[1]["le68_m"] == ""
    doc = json.loads(json_path.read_text())
    assert doc["counts"] == {"done": 1, "skipped": 1, "refused": 1, "failed": 0}
    assert [PairRow(**r) for r in doc["pairs"]] == list(rows)
    assert summary_csv(rows) == csv_path.read_text()


# each writer of a pair's products, killed (SIGKILL) at the instant it would rename its
# temporary result into place: what a worker process killed mid-write leaves behind
KILLED_WRITERS = {
    "json": "from tasks.io.rasters import atomic_write_json as w; w(OUT / 'report.json', {})",
    "cog": ("import numpy as np; from tasks.io.rasters import CogItem, write_arrays_cog as w; "
            "w([CogItem(np.zeros((8, 8), np.float32), OUT / 'dsm.tif')])"),
    "stac": "from tasks.archive.stac import write_catalog as w; w(OUT, 'p', [], 'd')",
}
KILL_AT_RENAME = """
import os, signal, sys
from pathlib import Path
OUT = Path(sys.argv[1])
def die(*args, **kwargs):
    os.kill(os.getpid(), signal.SIGKILL)
os.replace = os.rename = Path.rename = Path.replace = die
"""


def test_leftovers_of_killed_writers_are_found_and_removed_products_kept(tmp_path: Path):
    import signal
    import subprocess
    import sys

    from tasks.archive.pair import leftovers, remove_leftovers

    out = tmp_path / "p"
    touch(out / "report.json", "{}"), touch(out / "relative" / "report.json", "{}")
    touch(out / "stac" / "catalog.json", "{}"), touch(out / "report_files" / "a.png")
    repo = Path(__file__).resolve().parents[2]
    children = [subprocess.Popen([sys.executable, "-c", KILL_AT_RENAME + code, str(where)],
                                 cwd=repo, stderr=subprocess.PIPE, text=True)
                for where, code in ((out, KILLED_WRITERS["json"]),
                                    (out / "relative", KILLED_WRITERS["json"]),
                                    (out, KILLED_WRITERS["cog"]),
                                    (out, KILLED_WRITERS["stac"]))]
    for child in children:
        _, err = child.communicate(timeout=300)
        assert child.returncode == -signal.SIGKILL, err[-2000:]
    work = out / ".dsm.tif.work"  # the dense matching's work folder (flows.orient)
    touch(work / "tile_0.npz")
    products = {"report.json", "relative", "relative/report.json", "stac", "stac/catalog.json",
                "report_files", "report_files/a.png"}
    left = {str(p.relative_to(out)) for p in out.rglob("*")} - products
    assert len(left) >= 7  # each killed writer left its temporary names behind
    found = leftovers(out)
    names = sorted(str(p.relative_to(out)) for p in found)
    assert [n for n in names if n.startswith(".report.json.tmp")], names
    assert [n for n in names if n.startswith("relative/.report.json.tmp")], names
    assert [n for n in names if n.startswith(".dsm.tif.tmp")], names
    assert [n for n in names if n.startswith("_stac_tmp_")], names
    assert ".dsm.tif.work" in names
    # every temporary name is under one of those found (nothing listed twice)
    assert all(any(p == f or f in p.parents for f in found) for p in out.rglob("*")
               if str(p.relative_to(out)) not in products)
    assert remove_leftovers(out) == found
    assert {str(p.relative_to(out)) for p in out.rglob("*")} == products
    assert leftovers(out) == [] and remove_leftovers(tmp_path / "none") == []


def test_a_pair_whose_workers_kept_dying_is_failed_with_that_reason():
    from distributed import KilledWorker

    from tasks.archive.runs import failure_reason

    class Worker:  # what KilledWorker's message reads of the scheduler's WorkerState
        address = "tcp://127.0.0.1:40000"

    reason = failure_reason(KilledWorker("process_pair-1f2e", Worker(), 3))
    assert reason.startswith("the Dask worker process running this pair died 4 times (out of "
                             "memory, or killed)") and "rerun" in reason
    assert failure_reason(InputError("left image x.tif does not exist")) == (
        "left image x.tif does not exist")
    assert failure_reason(ValueError("bad\nvalue")) == "ValueError: bad"
