"""The dashboard as a person sees it: ``prefect server start`` on 127.0.0.1 (its own Prefect
home, offline), a finished ``reprocess-archive`` run sent to it, and the run's page of the
Prefect UI rendered in headless Chromium (Debian's, :mod:`tests.browser`): the run's name, its
flow, its state and its artifacts on the page, not just a page that loaded."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.browser import TIMEOUT_MS, chromium
from tests.flows.test_archive import FINISHED_EVAL, FINISHED_REPORT, complete_pair

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[2]
PREFECT = Path(sys.executable).parent / "prefect"
HEALTH_WAIT_S = 180.0
# a finished archive run (both pairs already complete: no orientation, no Dask), its id printed
RUN = ("import sys\n"
       "from flows._env import configure_environment\n"
       "configure_environment(verbose=False)\n"
       "from flows.reprocess_archive import reprocess_archive\n"
       "state = reprocess_archive(catalog=sys.argv[1], out=sys.argv[2], srtm_dir=sys.argv[3],\n"
       "                          return_state=True)\n"
       "print(state.state_details.flow_run_id, state.name)\n")
# the archive-map artifact's image, decoded and laid out
MAP_DRAWN = ("() => Array.from(document.images).some(i => i.src.startsWith("
             "'data:image/svg+xml') && i.complete && i.naturalWidth > 600)")
# what the page shows once the UI has drawn it: the run, or Prefect's "Page not found"
SHOWN = "name => document.body.innerText.includes(name)" \
        " || document.body.innerText.includes('Page not found')"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def server_env(home: Path, api: str) -> dict[str, str]:
    """The environment of a process talking to the test's server only (never the session's
    harness, whose settings live in this process), offline and quiet."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith(("PREFECT_API_", "PREFECT_SERVER_DATABASE", "PREFECT_PROFILES"))}
    return {**env, "PREFECT_HOME": str(home), "PREFECT_API_URL": api,
            "PREFECT_SERVER_ANALYTICS_ENABLED": "false", "DO_NOT_TRACK": "1",
            "PREFECT_LOGGING_TO_API_WHEN_MISSING_FLOW": "ignore",
            "DASK_TEMPORARY_DIRECTORY": str(home / "dask")}


@pytest.fixture
def prefect_server(tmp_path: Path) -> Iterator[tuple[str, dict[str, str]]]:
    """``prefect server start --host 127.0.0.1 --port <free>`` until healthy; (the server's
    address, the environment that sends runs to it). Stopped with SIGTERM at the end."""
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    env = server_env(tmp_path / "prefect", f"{url}/api")
    log = tmp_path / "server.log"
    with log.open("w") as out:
        proc = subprocess.Popen([str(PREFECT), "server", "start", "--host", "127.0.0.1",
                                 "--port", str(port)], cwd=tmp_path, env=env, stdout=out,
                                stderr=subprocess.STDOUT)
    try:
        end = time.monotonic() + HEALTH_WAIT_S
        while True:
            if proc.poll() is not None:
                pytest.fail(f"prefect server exited with {proc.returncode}: {log.read_text()}")
            try:
                if httpx.get(f"{url}/api/health", timeout=5).status_code == 200:
                    break
            except httpx.TransportError:
                pass
            if time.monotonic() > end:
                pytest.fail(f"prefect server not healthy after {HEALTH_WAIT_S:.0f} s: "
                            f"{log.read_text()}")
            time.sleep(0.5)
        yield url, env
    finally:
        proc.terminate()  # SIGTERM
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def finished_run(base: Path, env: dict[str, str]) -> str:
    """A ``reprocess-archive`` flow run sent to the server of ``env``: its id."""
    base.mkdir()
    (base / "cat.csv").write_text("id,left,right\nnorth,n/l.tif,n/r.tif\nsouth,s/l.tif,s/r.tif\n")
    complete_pair(base / "root" / "north", FINISHED_REPORT, FINISHED_EVAL)
    complete_pair(base / "root" / "south", {"gcps": {"used": 12}})
    done = subprocess.run([sys.executable, "-c", RUN, str(base / "cat.csv"), str(base / "root"),
                           str(base)], cwd=REPO, env=env, capture_output=True, text=True,
                          timeout=300, check=False)
    assert done.returncode == 0, done.stdout + done.stderr
    run_id, state = done.stdout.split()[-2:]
    assert state == "Completed", done.stdout + done.stderr
    return run_id


def wait_for_text(page: Any, script: str, arg: str, shot: Path) -> str:
    """The page's text once ``script(arg)`` holds; a failure with a screenshot and the text
    when it never does."""
    from playwright.sync_api import TimeoutError as PlaywrightTimeout

    try:
        page.wait_for_function(script, arg=arg)
    except PlaywrightTimeout:
        page.screenshot(path=str(shot))
        pytest.fail(f"{page.url} never showed {arg!r} in {TIMEOUT_MS / 1000:.0f} s "
                    f"(screenshot {shot}): {page.inner_text('body')[:2000]}")
    return page.inner_text("body")


def test_the_prefect_ui_shows_the_finished_run(prefect_server, tmp_path: Path):
    url, env = prefect_server
    run_id = finished_run(tmp_path / "archive", env)
    run = httpx.get(f"{url}/api/flow_runs/{run_id}", timeout=30).json()
    flow = httpx.get(f"{url}/api/flows/{run['flow_id']}", timeout=30).json()
    assert (flow["name"], run["state"]["name"]) == ("reprocess-archive", "Completed")
    # the run's INFO logs reach the server although the terminal shows only warnings
    logs = httpx.post(f"{url}/api/logs/filter", timeout=30, json={
        "logs": {"flow_run_id": {"any_": [run_id]}}}).json()
    finished = [entry["message"] for entry in logs if "Finished in state" in entry["message"]]
    assert finished, [entry["message"] for entry in logs]
    shot = tmp_path / "prefect_run.png"
    with chromium() as browser:
        page = browser.new_page(viewport={"width": 1280, "height": 900})
        page.set_default_timeout(TIMEOUT_MS)
        page.goto(f"{url}/runs/flow-run/{run_id}")
        wait_for_text(page, SHOWN, run["name"], shot)
        page.wait_for_load_state("networkidle")  # the timeline drawn, for the screenshot
        page.screenshot(path=str(shot))
        shown = page.inner_text("body")
        assert "Page not found" not in shown, f"the UI does not know run {run_id}"
        for text in (run["name"], flow["name"], "Completed"):
            assert text in shown, text
        logged = wait_for_text(page, "key => document.body.innerText.includes(key)",
                               "Finished in state", tmp_path / "prefect_logs.png")
        assert "Waiting for logs" not in logged
        page.get_by_text("Artifacts", exact=True).click()  # the run's tab
        artifacts = wait_for_text(page, "key => document.body.innerText.includes(key)",
                                  "archive-summary", tmp_path / "prefect_artifacts.png")
        page.screenshot(path=str(tmp_path / "prefect_artifacts.png"))
        # the archive's map (tasks.archive.map), its SVG drawn by the UI's markdown
        page.get_by_text("archive-map", exact=True).first.click()
        wait_for_text(page, "key => document.body.innerText.includes(key)",
                      "Archive map: 2 pairs", tmp_path / "prefect_map.png")
        page.wait_for_function(MAP_DRAWN)
        page.screenshot(path=str(tmp_path / "prefect_map.png"), full_page=True)
        # the same look on a run the server does not have: not shown, so the check can fail
        page.goto(f"{url}/runs/flow-run/{uuid.uuid4()}")
        absent = wait_for_text(page, SHOWN, run["name"], tmp_path / "prefect_absent.png")
    print(f"screenshots of the run page: {shot}, {tmp_path / 'prefect_artifacts.png'}, "
          f"{tmp_path / 'prefect_map.png'}")
    assert {"archive-summary", "archive-report", "archive-map"} <= {
        line.strip() for line in artifacts.splitlines()}
    assert "Page not found" in absent and run["name"] not in absent
