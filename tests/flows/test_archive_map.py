"""The archive on a map (issue 48 item 5): a 20-pair archive with two refusals and one failure
run by the real archive flow, its map page beside ``summary.csv`` seen in headless Chromium,
and the map refreshed, as an artifact, each time a pair ended.

Twenty real pairs would take ten minutes, so the archive is built as the archive makes it
with a stand-in for the pair chain only: 20 scene folders of the simulator's tiny geometry
(its delivered models beside empty images) laid over the bundled SRTM tile, their pairs found
by ``gcpfree scenes`` (the catalog with footprints), then ``reprocess_archive`` on that catalog
where each pair's run writes the products the map reads (``report.json`` with a stated
accuracy chosen per pair, the steps' products at known times), two pairs are refused by the
real relief verdict (``tasks.absolute.control.ground_control`` on a flat scene's verdict: the
InsufficientReliefError the chain raises) and one fails for real (its image removed).
"""

from __future__ import annotations

import base64
import json
import os
import re
import time
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tasks.io.geoid import BUNDLED_SRTM_DIR

DATA = Path(__file__).resolve().parents[1] / "data"
SVG = "{http://www.w3.org/2000/svg}"
REFUSED = (6, 13)  # the scenes whose pair is refused as too flat
FAILED = 9  # the scene whose image is removed
LONS, LATS = (5.16, 5.395, 5.63, 5.865), (44.12, 44.31, 44.50, 44.69, 44.88)


def stated_px(n: int) -> float:
    """The accuracy pair n states (its worst predicted check-point RMS): 0.10 .. 2.95 px."""
    return 0.10 + 0.15 * n


def step_s(k: int, n: int) -> float:
    """Seconds step k of pair n takes."""
    return (2.0 + 3.0 * k) * (1.0 + 0.1 * n)


def make_scenes(folder: Path) -> None:
    """20 pair folders (p00..p19, a 4 x 5 grid over N44E005): the tiny preset's delivered
    pushbroom models (left.json, right.json) beside images of their size without pixels."""
    import rasterio
    from rasterio.errors import NotGeoreferencedWarning

    from core.points import GeoPoint
    from core.simulation.scene import PRESETS, ErrorConfig, scene_models

    for n, (lat, lon) in enumerate((a, b) for a in LATS for b in LONS):
        pair = folder / f"p{n:02d}"
        pair.mkdir(parents=True)
        models = scene_models(PRESETS["tiny"], GeoPoint(lon, lat, 1000.0), ErrorConfig(), n)
        for name, m in models.items():
            (pair / f"{name}.json").write_text(m.delivered.to_json(indent=1))
            with warnings.catch_warnings():  # a raw sensor image has no georeference
                warnings.simplefilter("ignore", NotGeoreferencedWarning)
                with rasterio.open(pair / f"{name}.tif", "w", driver="GTiff", count=1,
                                   width=m.delivered.n_cols, height=m.delivered.n_rows,
                                   dtype="uint8", tiled=True, sparse_ok=True):
                    pass


def stand_in_chain(entry: Any, root: Path, *args: Any, **kwargs: Any) -> None:
    """What ``run_pair`` leaves, quickly: a refusal from the relief verdict, or the products
    the map reads (each step's last product written ``step_s`` after the previous one)."""
    from core.matching.relief import ReliefVerdict
    from core.orientation.absolute import AbsoluteConfig
    from tasks.absolute.control import ground_control
    from tasks.archive.map import STEPS

    n = int(entry.id[1:3])
    if n in REFUSED:  # 2 of 41 windows with the relief of 3 m: the chain's own refusal
        flat = ReliefVerdict(n_windows=41, n_qualified=2, n_needed=8, relief_found_m=3.1,
                             relief_needed_m=10.7, max_precision_m=20.0)
        ground_control.fn(None, flat, None, AbsoluteConfig())
    out = Path(root) / entry.id
    t = time.time()
    for k, (_, product) in enumerate(STEPS):
        path = out / product
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("{}")
        t += step_s(k, n)
        os.utime(path, (t, t))
    report = json.loads((DATA / "products_v0_1" / "report.json").read_text())
    images = report["absolute"]["predicted"]["images"]
    worst = max(v[k] for v in images.values() for k in ("predicted_rms_col_px",
                                                          "predicted_rms_row_px"))
    for v in images.values():
        for k in ("predicted_rms_col_px", "predicted_rms_row_px"):
            v[k] *= stated_px(n) / worst
    (out / "report.json").write_text(json.dumps(report))


@pytest.fixture(scope="module")
def archive20(tmp_path_factory, prefect_harness):
    """The archive run: (catalog document, ROOT, outcome, the flow run's id)."""
    import flows.reprocess_archive as archive_flow
    from flows.cli import main

    base = tmp_path_factory.mktemp("archive20")
    make_scenes(base / "scenes")
    assert main(["scenes", str(base / "scenes"), "--out", str(base / "scenes.json")]) == 0
    (base / "scenes" / f"p{FAILED:02d}" / "left.tif").unlink()
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(archive_flow, "run_pair", stand_in_chain)
        state = archive_flow.reprocess_archive(
            catalog=base / "scenes.json", out=base / "root", srtm_dir=BUNDLED_SRTM_DIR,
            workers=2, processes=False, dashboard_address=":0", return_state=True)
    doc = json.loads((base / "scenes.json").read_text())
    return doc, base / "root", state.result(), state.state_details.flow_run_id


def pair_number(pair_id: str) -> int:
    return int(pair_id[1:3])


def polygons(svg_text: str) -> list[ET.Element]:
    return [p for p in ET.fromstring(svg_text).iter(f"{SVG}polygon") if p.get("class") == "pair"]


def test_the_scenes_catalog_holds_the_20_pairs_and_their_footprints(archive20):
    doc, _, outcome, _ = archive20
    assert len(doc["pairs"]) == 20 and len(doc["scenes"]) == 40
    assert all(len(s["footprint"]) == 4 for s in doc["scenes"])
    assert {r.status for r in outcome.rows} == {"done", "refused", "failed"}


def test_the_map_shows_every_pair_by_its_summary_status(archive20):
    """Both panels draw the 20 pairs, each with the status summary.csv gives it: 17 done, the
    two flat ones refused with the relief verdict's words, the one without its image
    failed."""
    import csv
    import io

    _, root, _, _ = archive20
    summary = {r["id"]: r for r in csv.DictReader(io.StringIO((root / "summary.csv").read_text()))}
    want = {i: ("refused" if pair_number(i) in REFUSED else
                "failed" if pair_number(i) == FAILED else "done") for i in summary}
    assert {i: r["status"] for i, r in summary.items()} == want
    svg = (root / "map.svg").read_text()
    drawn = polygons(svg)
    assert len(drawn) == 40
    for panel in (drawn[:20], drawn[20:]):
        assert {p.get("data-id"): p.get("data-status") for p in panel} == want
    page = (root / "map.html").read_text()
    assert svg in page
    assert "20 pairs: 17 done, 2 refused, 1 failed, 0 running, 0 queued" in page
    for i, status in want.items():
        if status == "refused":
            assert summary[i]["reason"].startswith("the terrain is too flat")
        if status != "done":
            assert summary[i]["reason"] and summary[i]["reason"] in page.replace("&#x27;", "'")


def test_the_second_panel_colours_the_stated_accuracy(archive20):
    from tasks.archive.map_render import ACCURACY_BINS, NO_FIGURE

    _, root, _, _ = archive20
    bounds = [hi for hi, _ in ACCURACY_BINS]
    for p in polygons((root / "map.svg").read_text())[20:]:
        n = pair_number(p.get("data-id"))
        if p.get("data-status") == "done":  # the bin of the accuracy that pair states
            b = int(np.searchsorted(bounds, stated_px(n) - 1e-9))
            assert p.get("fill") == ACCURACY_BINS[b][1], (n, stated_px(n))
        else:
            assert p.get("fill") == NO_FIGURE


def test_the_slowest_steps_are_read_from_the_products_times(archive20):
    from tasks.archive.map import STEPS
    from tasks.archive.map_render import seconds_text

    _, root, _, _ = archive20
    done = [n for n in range(20) if n not in (*REFUSED, FAILED)]
    page = (root / "map.html").read_text()
    last = len(STEPS) - 1  # the longest step, slowest on the last pair
    row = (f"<td>{STEPS[last][0]}</td><td>17</td>"
           f"<td>{seconds_text(sum(step_s(last, n) for n in done))}</td>")
    assert row in page
    assert f"{seconds_text(step_s(last, max(done)))} (p{max(done):02d}_" in page
    order = [page.index(f"<td>{s}</td><td>17</td>") for s, _ in reversed(STEPS)]
    assert order == sorted(order)


def test_the_map_was_refreshed_as_each_pair_ended(archive20):
    """The artifact ``archive-map`` of the run got a version when the run began, one per pair
    ended (the count of ended pairs growing by one) and the last one: the map of the page."""
    from prefect.client.orchestration import get_client
    from prefect.client.schemas.filters import ArtifactFilter, ArtifactFilterKey
    from prefect.client.schemas.sorting import ArtifactSort

    _, root, _, run_id = archive20
    with get_client(sync_client=True) as client:
        run = client.read_flow_run(run_id)
        versions = client.read_artifacts(
            artifact_filter=ArtifactFilter(key=ArtifactFilterKey(any_=["archive-map"])),
            sort=ArtifactSort.CREATED_DESC)[::-1]
    # this run's versions: the session's other archives publish the same key (the pairs'
    # refreshes come from threads of the flow, outside its run context: no flow run id)
    versions = [a for a in versions if run.start_time <= a.created <= run.end_time]
    ended = []
    for a in versions:
        running, queued = re.search(r"\*\*20 pairs: .* (\d+) running, (\d+) queued\*\*",
                                    a.data).groups()
        ended.append(20 - int(running) - int(queued))
    assert ended == [0, *range(1, 21), 20]
    last = versions[-1].data
    svg = base64.b64decode(last.split("data:image/svg+xml;base64,")[1].split(")")[0]).decode()
    assert svg == (root / "map.svg").read_text()


# ---------------------------------------------------------------------------- as seen


LOOK = """() => ({width: document.documentElement.scrollWidth, window: window.innerWidth,
                 pairs: document.querySelectorAll('svg polygon.pair').length,
                 refused: document.querySelectorAll('polygon[data-status=refused]').length,
                 shade: document.querySelectorAll('svg #shade').length})"""


@pytest.mark.slow
def test_the_map_page_in_headless_chromium(archive20, tmp_path):
    """The page as a reader sees it on a desktop and a phone: both maps drawn with their 20
    pairs (the two refused among them), nothing fetched from outside the file, no sideways
    scrolling; the hillshade shows under the pairs (the panels look different without it)."""
    from PIL import Image

    from tests.browser import TIMEOUT_MS, chromium

    _, root, _, _ = archive20
    outside: list[str] = []
    shots = {}
    with chromium() as browser:
        for width in (1280, 390):
            page = browser.new_page(viewport={"width": width, "height": 900})
            page.set_default_timeout(TIMEOUT_MS)
            page.route("**/*", lambda route: (route.continue_() if route.request.url.startswith(
                "file:") else (outside.append(route.request.url), route.abort())))
            page.goto((root / "map.html").as_uri(), wait_until="load")
            look = page.evaluate(LOOK)
            assert look["width"] <= look["window"], (width, look)
            assert (look["pairs"], look["refused"], look["shade"]) == (40, 4, 1)
            if width == 1280:
                box = page.locator(".map svg").bounding_box()
                shots["with"] = tmp_path / "map.png"
                page.screenshot(path=str(shots["with"]), clip=box)
                page.screenshot(path=str(tmp_path / "map_page.png"), full_page=True)
                page.evaluate("() => document.querySelectorAll('svg use').forEach(u => u.remove())")
                shots["without"] = tmp_path / "map_without_shade.png"
                page.screenshot(path=str(shots["without"]), clip=box)
            page.close()
    print(f"screenshots: {tmp_path / 'map_page.png'}, {shots['with']}")
    assert not outside, outside
    a, b = (np.asarray(Image.open(shots[k]).convert("L"), dtype=float) for k in ("with", "without"))
    assert a.shape == b.shape
    changed = np.abs(a - b) > 8
    assert changed.mean() > 0.2, changed.mean()  # the relief covers the panels


# ---------------------------------------------------------------------------- pieces


def test_the_hillshade_png_reads_back_exactly():
    import io

    from matplotlib import image

    from tasks.archive.map import grey_png

    g = (np.arange(37 * 53).reshape(37, 53) * 7 % 256).astype(np.uint8)
    back = image.imread(io.BytesIO(grey_png(g)), format="png")  # Pillow decodes it
    assert back.shape == g.shape and np.array_equal(np.round(back * 255), g)


def test_a_pair_is_drawn_where_its_images_overlap():
    from tasks.archive.map import overlap

    a = ((0.0, 0.0), (0.0, 1.0), (1.0, 1.0), (1.0, 0.0))  # clockwise
    b = ((0.5, 0.25), (1.5, 0.25), (1.5, 2.0), (0.5, 2.0))
    poly = np.array(overlap(a, b))
    x, y = poly[:, 0], poly[:, 1]
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))
    assert area == pytest.approx(0.5 * 0.75)
    assert x.min() == pytest.approx(0.5) and y.min() == pytest.approx(0.25)
    far = ((5.0, 5.0), (6.0, 5.0), (6.0, 6.0), (5.0, 6.0))
    assert len(overlap(a, far)) == 4  # apart: the first image's own footprint
