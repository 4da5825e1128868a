"""``gcpfree archive`` on a catalog of four pairs: a real tiny pair (oriented for real by the
session's run on a separately started Dask cluster, its folder left with the products up to
its orthos, as an interrupted run leaves it), a pair whose products are already complete
(skipped), a pair without images and one with malformed metadata (each failed with its
reason, the others unaffected); the summary files agree with the products; a rerun processes
only the failed pair. The runs are the session fixtures of tests/flows/conftest.py."""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
from pathlib import Path

import pytest

from core.errors import InputError
from flows.commands import archive as archive_command
from tests.flows.reports import finished_evaluation, finished_report


def complete_pair(out: Path, report: dict, evaluation: dict | None = None,
                  params: dict | None = None) -> None:
    """The minimal finished products :func:`tasks.archive.pair.pair_complete` accepts: the
    manifest ``pair.json`` listing products that read back with their recorded sizes (and the
    parameters it was made with)."""
    out.mkdir(parents=True)
    products = {"report": "report.json"}
    (out / "report.json").write_text(json.dumps(report))
    if evaluation is not None:
        (out / "eval.json").write_text(json.dumps(evaluation))
        products["evaluation"] = "eval.json"
    (out / "pair.json").write_text(json.dumps({
        "format": "gcpfree.pair", "version": 1, "pair_id": out.name, "products": products,
        **({"params": params} if params is not None else {}),
        "sizes": {rel: (out / rel).stat().st_size for rel in products.values()}}))


FINISHED_REPORT = finished_report(41, {"left": (0.25, 0.5), "right": (0.75, 0.125)},
                                  {"left": (0.375, 0.625), "right": (0.875, 0.0625)})
FINISHED_EVAL = finished_evaluation(3.5)


def parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="gcpfree")
    archive_command.add_parser(parser.add_subparsers(dest="command"))
    return parser.parse_args(["archive", *argv])


def snapshot(folder: Path) -> dict[str, tuple[bytes, int]]:
    return {str(p.relative_to(folder)): (p.read_bytes(), p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*")) if p.is_file()}


# the first run on the four pairs: the session fixture ``archive`` of tests/flows/conftest.py


def test_each_pair_ends_done_skipped_or_failed_with_its_reason(archive):
    from tasks.archive.pair import pair_complete

    _, _, root, outcome, _, _, before = archive
    status = {r.id: r.status for r in outcome.rows}
    assert status == {"badmeta": "failed", "broken": "failed", "finished": "skipped",
                      "real": "done"}
    reason = {r.id: r.reason for r in outcome.rows}
    assert reason["broken"].startswith(f"left image {root.parent}/catalog/broken/left.tif "
                                       "does not exist")
    assert "left.json" in reason["badmeta"] and "\n" not in reason["badmeta"]
    assert reason["real"] == reason["finished"] == ""
    assert pair_complete(root / "real")  # the failing pair did not stop it
    assert snapshot(root / "finished") == before  # skipped: not a byte or a time changed
    assert not (root / "broken" / "pair.json").exists()
    assert outcome.dashboard and outcome.dashboard.startswith("http")
    # the link is also on the server, as an artifact of the run that used the cluster
    from prefect.client.orchestration import get_client
    from prefect.client.schemas.filters import ArtifactFilter, ArtifactFilterKey

    with get_client(sync_client=True) as client:
        links = client.read_artifacts(artifact_filter=ArtifactFilter(
            key=ArtifactFilterKey(any_=["dask-dashboard"])))
    assert any(outcome.dashboard in (a.data or "") for a in links)


def test_summary_files_agree_with_the_products(archive):
    _, _, root, _, csv_text, doc, _ = archive
    rows = {r["id"]: r for r in csv.DictReader(io.StringIO(csv_text))}
    assert list(rows) == ["badmeta", "broken", "finished", "real"]  # catalog order
    report = json.loads((root / "real" / "report.json").read_text())
    real = rows["real"]
    assert int(real["gcps"]) == report["gcps"]["used"] >= 8
    for side in ("left", "right"):
        for axis in ("col", "row"):
            cp = report["check_points"][side][f"rms_{axis}_px"]
            assert float(real[f"cp_{side}_rms_{axis}_px"]) == pytest.approx(cp, rel=1e-5)
            assert cp < 1.0  # oriented to the check points with no GCP (40 m pixels)
            g = report["absolute"]["images"][side][f"rms_{axis}_px"]
            assert float(real[f"gcp_{side}_rms_{axis}_px"]) == pytest.approx(g, rel=1e-5)
    assert real["le68_m"] == ""  # no lidar in this scene
    fin = rows["finished"]
    assert (fin["gcps"], fin["cp_right_rms_row_px"], fin["gcp_left_rms_row_px"],
            fin["le68_m"]) == ("41", "0.0625", "0.5", "3.5")
    assert rows["broken"]["gcps"] == "" and "does not exist" in rows["broken"]["reason"]
    assert doc["counts"] == {"done": 1, "skipped": 1, "refused": 0, "failed": 2}
    assert [(p["id"], p["status"], p["reason"]) for p in doc["pairs"]] == [
        (r["id"], r["status"], r["reason"]) for r in rows.values()]
    assert doc["pairs"][3]["cp_left_rms_col_px"] == report["check_points"]["left"]["rms_col_px"]
    assert not [p.name for p in root.iterdir() if p.name.startswith(".")]  # no temp file left


def test_rerun_processes_only_the_failed_pair(archive, capsys):
    scene, cat, root, _, _, _, _ = archive
    real_before = snapshot(root / "real")
    # the lost images come back, but corrupt: the pair is attempted again and fails otherwise
    for side in ("left", "right"):
        (cat / "broken" / f"{side}.tif").write_bytes(b"II*\x00truncated")
    rc = archive_command.run(parse(
        "--catalog", str(cat), "--out", str(root), "--reference", str(scene / "reference.tif"),
        "--workers", "1", "--threads", "--dashboard-address", ":0", "--no-progress"))
    assert rc == 1  # a pair failed
    printed = capsys.readouterr().out
    assert "Dask dashboard" in printed and "2 failed" in printed
    rows = {r["id"]: r for r in csv.DictReader(io.StringIO((root / "summary.csv").read_text()))}
    assert {k: r["status"] for k, r in rows.items()} == {
        "badmeta": "failed", "broken": "failed", "finished": "skipped", "real": "skipped"}
    assert rows["broken"]["reason"] and "does not exist" not in rows["broken"]["reason"]
    assert "\n" not in rows["broken"]["reason"]
    assert snapshot(root / "real") == real_before  # not processed again
    assert float(rows["real"]["cp_left_rms_col_px"]) > 0  # figures still read from products


def test_the_options_reach_every_pair_through_the_flow(tmp_path: Path, prefect_harness):
    """The flow's ``options`` (every pair) and the catalog's own (one pair) decide which pairs
    are complete, and reach each pair's run in its Dask worker: two pairs finished with
    them are skipped; the same archive with a bad option fails both pairs with its reason,
    their products untouched."""
    from flows.options import OPTIONS
    from flows.reprocess_archive import pair_params, reprocess_archive
    from tasks.archive.catalog import read_catalog

    cat, root, ref = tmp_path / "cat.csv", tmp_path / "root", tmp_path / "ref.tif"
    cat.write_text("id,left,right,corrections\nown,own/l.tif,own/r.tif,offset\n"
                   "plain,plain/l.tif,plain/r.tif,\n")
    for name in ("own/l.tif", "own/r.tif", "plain/l.tif", "plain/r.tif"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_text("not read: the pairs are complete or refused first")
    options = {"self_calibrate": True, "surface.radius_m": 3000}
    for entry in read_catalog(cat, tuple(OPTIONS)).pairs:
        complete_pair(root / entry.id, FINISHED_REPORT, params=json.loads(json.dumps(
            pair_params(entry, root, None, ref, options=options).to_dict())))
    before = {i: snapshot(root / i) for i in ("own", "plain")}

    def run(**extra):
        outcome = reprocess_archive(catalog=cat, out=root, reference=ref, workers=1,
                                    processes=False, dashboard_address=":0", **extra)
        return {r.id: (r.status, r.reason) for r in outcome.rows}

    assert run(options=options) == {"own": ("skipped", ""), "plain": ("skipped", "")}
    found = run(options={**options, "surface.radius_m": -5.0})
    assert {k: s for k, (s, _) in found.items()} == {"own": "failed", "plain": "failed"}
    for pair_id, (_, reason) in found.items():
        assert reason.startswith("the archive's options: surface matching needs a window "
                                 "radius > 0 m"), reason
        assert snapshot(root / pair_id) == before[pair_id]


def test_bad_arguments_are_one_line_before_prefect(tmp_path: Path):
    (tmp_path / "cat.csv").write_text("id,left,right\n")
    with pytest.raises(InputError, match="lists no pair"):
        archive_command.run(parse("--catalog", str(tmp_path / "cat.csv"), "--out",
                                  str(tmp_path / "o"), "--srtm-dir", str(tmp_path)))
    (tmp_path / "cat.csv").write_text("id,left,right\np,l.tif,r.tif\n")
    for extra, message in ((["--workers", "0"], "--workers must be at least 1"),
                           (["--dask-address", "localhost"], "tcp://HOST:PORT")):
        with pytest.raises(InputError, match=message):
            archive_command.run(parse("--catalog", str(tmp_path / "cat.csv"), "--out",
                                      str(tmp_path / "o"), "--srtm-dir", str(tmp_path), *extra))
    with pytest.raises(InputError, match="DEM tile folder .* does not exist"):
        archive_command.run(parse("--catalog", str(tmp_path / "cat.csv"), "--out",
                                  str(tmp_path / "o"), "--srtm-dir", str(tmp_path / "none")))
    with pytest.raises(SystemExit):  # the ground is required: --srtm-dir or --reference
        parse("--catalog", str(tmp_path / "cat.csv"), "--out", str(tmp_path / "o"))


# the run on a separately started cluster: the session fixture ``external_archive`` of
# tests/flows/conftest.py


def test_archive_on_a_separately_started_dask_cluster(external_archive):
    """The pairs run on the external cluster, not on a LocalCluster the flow might start
    instead (a link on 127.0.0.1 proves nothing: a LocalCluster can serve its dashboard there
    too): the external scheduler's task stream holds both pairs' tasks, run by the worker
    process the fixture started, the real pair's for the seconds an orientation takes; the
    dashboard link is the external scheduler's."""
    from dask.utils import key_split

    from tasks.archive.pair import pair_complete

    run = external_archive
    root, outcome, cluster, stream, pids = (run.root, run.outcome, run.cluster, run.stream,
                                            run.pids)
    assert {r.id: r.status for r in outcome.rows} == {"broken": "failed", "real": "done"}
    assert pair_complete(root / "real")
    assert outcome.dashboard and outcome.dashboard.startswith(
        f"http://127.0.0.1:{cluster.dashboard_port}/")
    report = json.loads((root / "real" / "report.json").read_text())
    assert outcome.rows[1].gcps == report["gcps"]["used"] >= 8
    assert list(pids.values()) == [cluster.worker_pid] != [os.getpid()]
    # one task per pair (both end "memory": a failing pair returns its reason), on that worker
    assert len(stream) == 2, stream
    assert {key_split(t["key"]) for t in stream} == {"process_pair"}
    assert {pids[t["worker"]] for t in stream} == {cluster.worker_pid}
    seconds = sorted(sum(s["stop"] - s["start"] for s in t["startstops"]
                         if s["action"] == "compute") for t in stream)
    # the broken pair, the real orientation (measured 0.2 s and 23 s)
    assert seconds[0] < 5.0 < seconds[1], seconds
