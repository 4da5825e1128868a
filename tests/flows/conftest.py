"""Fixtures the flow tests share across files."""

from __future__ import annotations

import json

import pytest


@pytest.fixture(scope="session")
def archive(tiny_clean_scene, tmp_path_factory, prefect_harness):
    """``gcpfree archive``'s first run on four pairs (tests/flows/test_archive.py), on a
    LocalCluster of one thread worker: (scene, catalog, root, outcome, summary.csv text,
    summary.json document, the finished pair's files before the run). Its real pair, oriented
    for real, is also the finished pair the interrupted archives of test_archive_kill.py copy
    (made once per session: an orientation of the tiny pair takes 20-30 s)."""
    from flows.reprocess_archive import pair_params, reprocess_archive
    from tasks.archive.catalog import load_catalog
    from tests.flows.test_archive import FINISHED_EVAL, FINISHED_REPORT, complete_pair, snapshot

    scene, _ = tiny_clean_scene
    base = tmp_path_factory.mktemp("archive")
    cat, root = base / "catalog", base / "root"
    cat.mkdir()
    (cat / "real").symlink_to(scene)  # the simulator's folder: left.tif, right.tif, truth/
    (cat / "finished").mkdir()  # no images: processing it would fail
    (cat / "broken").mkdir()
    (cat / "broken" / "notes.txt").write_text("images lost")
    bad = cat / "badmeta"  # the real images, the left one's metadata malformed
    bad.mkdir()
    for name in ("left.tif", "right.tif", "right.json"):
        (bad / name).symlink_to(scene / name)
    (bad / "left.json").write_text('{"format": "gcpfree.pushbroom", "orbit": [1, 2')
    # finished by an earlier run of this archive with the same options (its images since lost)
    entry = next(e for e in load_catalog(cat).pairs if e.id == "finished")
    complete_pair(root / "finished", FINISHED_REPORT, FINISHED_EVAL,
                  json.loads(json.dumps(pair_params(entry, root, None,
                                                    scene / "reference.tif").to_dict())))
    before = snapshot(root / "finished")
    outcome = reprocess_archive(catalog=cat, out=root, reference=scene / "reference.tif",
                                workers=1, processes=False, dashboard_address=":0")
    return (scene, cat, root, outcome, (root / "summary.csv").read_text(),
            json.loads((root / "summary.json").read_text()), before)
