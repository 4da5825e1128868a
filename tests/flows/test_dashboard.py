"""What the dashboard shows: the archive flow run against a local Prefect server (the test
harness), its run, task runs and artifacts read back through the Prefect client."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.flows.reports import finished_report
from tests.flows.test_archive import FINISHED_EVAL, FINISHED_REPORT, complete_pair


@pytest.fixture(scope="module")
def finished_archive(tmp_path_factory, prefect_harness):
    """An archive whose two pairs are already complete (fast: no orientation, no Dask); the
    flow run's final state."""
    from flows.reprocess_archive import reprocess_archive

    base = tmp_path_factory.mktemp("dashboard")
    (base / "cat.csv").write_text("id,left,right\nnorth,n/l.tif,n/r.tif\nsouth,s/l.tif,s/r.tif\n")
    complete_pair(base / "root" / "north", FINISHED_REPORT, FINISHED_EVAL)
    complete_pair(base / "root" / "south", finished_report(12, {"left": (0.5, 0.5)}))
    state = reprocess_archive(catalog=base / "cat.csv", out=base / "root",
                              srtm_dir=base, return_state=True)
    return base, state


def test_run_and_task_runs_are_on_the_server(finished_archive):
    from prefect.client.orchestration import get_client
    from prefect.client.schemas.filters import FlowRunFilter, FlowRunFilterId

    _, state = finished_archive
    assert state.is_completed()
    run_id = state.state_details.flow_run_id
    with get_client(sync_client=True) as client:
        run = client.read_flow_run(run_id)
        flow = client.read_flow(run.flow_id)
        tasks = client.read_task_runs(
            flow_run_filter=FlowRunFilter(id=FlowRunFilterId(any_=[run_id])))
    assert flow.name == "reprocess-archive" and run.state.is_completed()
    assert run.parameters["srtm_dir"].endswith("dashboard0")
    names = {t.name.rsplit("-", 1)[0] for t in tasks}
    assert {"read-catalog", "find-complete-pairs", "write-archive-summary",
            "publish-archive-summary"} <= names
    assert all(t.state.is_completed() for t in tasks)


def test_artifacts_hold_the_summary(finished_archive):
    from prefect.client.orchestration import get_client
    from prefect.client.schemas.filters import ArtifactFilter, ArtifactFilterFlowRunId

    base, state = finished_archive
    with get_client(sync_client=True) as client:
        artifacts = client.read_artifacts(artifact_filter=ArtifactFilter(
            flow_run_id=ArtifactFilterFlowRunId(any_=[state.state_details.flow_run_id])))
    by_key = {a.key: a for a in artifacts}
    assert {"archive-summary", "archive-report"} <= set(by_key)
    table = by_key["archive-summary"]
    assert table.type == "table"
    rows = json.loads(table.data) if isinstance(table.data, str) else table.data
    summary = json.loads((Path(base) / "root" / "summary.json").read_text())
    assert rows == summary["pairs"]  # the table is summary.json's list, row for row
    assert [(r["id"], r["status"], r["gcps"], r["le68_m"]) for r in rows] == [
        ("north", "skipped", 41, 3.5), ("south", "skipped", 12, None)]
    report = by_key["archive-report"]
    assert report.type == "markdown"
    assert "0 done, 2 skipped (already complete), 0 failed" in report.data
    assert str(base / "root" / "summary.csv") in report.data
