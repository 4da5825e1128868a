"""Schedules: ``gcpfree serve`` registers the archive deployment with its cron schedule on a
local Prefect API (the test harness's server) and serves it; ``prefect.yaml`` describes the
same flow and deploys with ``prefect deploy``. Both read back through the Prefect client."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from core.errors import InputError
from flows.commands import serve as serve_command

REPO = Path(__file__).resolve().parents[2]
PREFECT = Path(sys.executable).parent / "prefect"
# `gcpfree serve` whether or not flows/cli.py lists the command yet
SERVE = ("import argparse, sys\n"
         "from flows._env import configure_environment\n"
         "configure_environment(verbose=False)\n"
         "from flows.commands import serve\n"
         "p = argparse.ArgumentParser(prog='gcpfree')\n"
         "serve.add_parser(p.add_subparsers(dest='command'))\n"
         "sys.exit(serve.run(p.parse_args(['serve', *sys.argv[1:]])))\n")
CRON = "30 4 29 2 *"  # 04:30 on 29 February: registered, never fired during a test


def parse(*argv: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="gcpfree")
    serve_command.add_parser(parser.add_subparsers(dest="command"))
    return parser.parse_args(["serve", *argv])


def read_deployment(name: str, proc: subprocess.Popen | None = None, log: Path | None = None,
                    wait_s: float = 180.0):
    """The deployment ``flow/deployment`` from the API, waiting while ``proc`` registers it."""
    from prefect.client.orchestration import get_client
    from prefect.exceptions import ObjectNotFound

    end = time.monotonic() + wait_s
    with get_client(sync_client=True) as client:
        while True:
            try:
                return client.read_deployment_by_name(name)
            except ObjectNotFound:
                if proc is None or time.monotonic() > end:
                    raise
                if proc.poll() is not None:
                    pytest.fail(f"serve exited with {proc.returncode}: {log.read_text()}")
                time.sleep(0.5)


def api_env(**extra: str) -> dict[str, str]:
    from prefect.settings import PREFECT_API_URL

    return {**os.environ, "PREFECT_API_URL": PREFECT_API_URL.value(), **extra}


def test_serve_registers_the_deployment_with_its_cron(prefect_harness, tmp_path: Path):
    from prefect.client.orchestration import get_client

    (tmp_path / "cat.csv").write_text("id,left,right\np1,a/l.tif,a/r.tif\n")
    log = tmp_path / "serve.log"
    with log.open("w") as out:
        proc = subprocess.Popen(
            [sys.executable, "-c", SERVE, "--catalog", str(tmp_path / "cat.csv"),
             "--out", str(tmp_path / "root"), "--srtm-dir", str(tmp_path), "--cron", CRON,
             "--timezone", "Europe/Paris", "--name", "test-nightly", "--workers", "2",
             "--self-calibrate", "--window-radius", "3000", "--reference-sigma", "2", "2", "4"],
            cwd=REPO, env=api_env(), stdout=out, stderr=subprocess.STDOUT)
        try:
            dep = read_deployment("reprocess-archive/test-nightly", proc, log)
        finally:
            proc.terminate()  # SIGTERM: a served process ignores SIGINT when not interactive
            try:
                proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    with get_client(sync_client=True) as client:
        flow = client.read_flow(dep.flow_id)
    assert flow.name == "reprocess-archive"
    assert dep.entrypoint.endswith("reprocess_archive.py:reprocess_archive")
    [sched] = dep.schedules
    assert (sched.schedule.cron, sched.schedule.timezone) == (CRON, "Europe/Paris")
    assert dep.parameters == {
        "catalog": str(tmp_path / "cat.csv"), "out": str(tmp_path / "root"),
        "srtm_dir": str(tmp_path), "reference": None, "reference_vertical": "auto",
        "geoid": None, "dask_address": None, "workers": 2,
        "processes": True, "dashboard_address": ":8787",
        # the orientation options given, by their names in pair.json (the others at defaults)
        "options": {"self_calibrate": True, "surface.radius_m": 3000.0,
                    "reference_sigma_m": [2.0, 2.0, 4.0]}}
    assert {"gcpfree", "archive"} <= set(dep.tags)
    assert "serving" in log.read_text() and CRON in log.read_text()


def test_prefect_yaml_deploys_the_same_flow(prefect_harness, tmp_path: Path):
    from prefect.flows import load_flow_from_entrypoint

    from flows.reprocess_archive import reprocess_archive

    doc = yaml.safe_load((REPO / "prefect.yaml").read_text())
    [spec] = doc["deployments"]
    flow = load_flow_from_entrypoint(str(REPO / spec["entrypoint"]))
    assert flow.name == reprocess_archive.name
    # every parameter the command line sets, and only the flow's own
    assert set(spec["parameters"]) == set(reprocess_archive.parameters.properties) - {"progress"}
    env = api_env(GCPFREE_CATALOG=str(tmp_path / "cat.csv"), GCPFREE_ROOT=str(tmp_path / "out"),
                  GCPFREE_SRTM_DIR=str(tmp_path / "srtm"))
    for cmd in ([str(PREFECT), "work-pool", "create", spec["work_pool"]["name"], "--type",
                 "process"],
                [str(PREFECT), "--no-prompt", "deploy", "--name", spec["name"]]):
        done = subprocess.run(cmd, cwd=REPO, env=env, capture_output=True, text=True, check=False,
                              timeout=300)
        assert done.returncode == 0, done.stdout + done.stderr
    dep = read_deployment(f"reprocess-archive/{spec['name']}")
    [sched] = dep.schedules
    assert (sched.schedule.cron, sched.schedule.timezone, sched.active) == (
        serve_command.DEFAULT_CRON, "UTC", True)
    assert dep.entrypoint == "flows/reprocess_archive.py:reprocess_archive"
    assert dep.work_pool_name == "gcpfree"
    assert dep.parameters["catalog"] == str(tmp_path / "cat.csv")
    assert dep.parameters["out"] == str(tmp_path / "out")
    assert dep.parameters["srtm_dir"] == str(tmp_path / "srtm")
    assert reprocess_archive.validate_parameters(dep.parameters)["out"] == tmp_path / "out"
    assert dep.pull_steps == [{"prefect.deployments.steps.set_working_directory":
                               {"directory": str(REPO)}}]


@pytest.mark.parametrize(("cron", "tz", "message"), [
    ("61 * * * *", "UTC", "Invalid cron string"),
    ("0 2 * * *", "Mars/Base", "Invalid timezone"),
])
def test_bad_schedule_is_one_line(tmp_path: Path, cron: str, tz: str, message: str):
    (tmp_path / "cat.csv").write_text("id,left,right\np1,l.tif,r.tif\n")
    with pytest.raises(InputError, match=message) as err:
        serve_command.run(parse("--catalog", str(tmp_path / "cat.csv"), "--out", str(tmp_path),
                                "--srtm-dir", str(tmp_path), "--cron", cron, "--timezone", tz))
    assert "\n" not in str(err.value)


def test_serve_without_a_server_says_how_to_start_one(tmp_path: Path):
    from prefect.settings import PREFECT_API_URL, temporary_settings

    (tmp_path / "cat.csv").write_text("id,left,right\np1,l.tif,r.tif\n")
    with temporary_settings(restore_defaults={PREFECT_API_URL}), \
            pytest.raises(InputError, match="prefect server start --host 127.0.0.1"):
        serve_command.run(parse("--catalog", str(tmp_path / "cat.csv"), "--out", str(tmp_path),
                                "--srtm-dir", str(tmp_path)))
