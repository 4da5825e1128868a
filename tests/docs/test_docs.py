"""The documentation site (``docs/``, ``make docs``): the tutorials' commands are real (each
``gcpfree ...`` line parses with the real parser), every command of the registry has its
generated page with all its options, every product its page, and the built site, looked at in
headless Chromium as a reader does, shows every page with its figures, no page scrolling
sideways and no request leaving the site.

The site is built once per session (strict, as ``make docs``: a warning fails it) into a
temporary folder. Without the ``docs`` extra (Sphinx, MyST, furo) or chromium the build and
browser tests skip, except where ``GCPFREE_REQUIRE_BROWSER`` is set (``.ci/run``), where they
fail: CI installs both (``make test``'s environment has ``.[test,docs]``).
"""

from __future__ import annotations

import argparse
import atexit
import importlib.util
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from flows.cli import COMMAND_MODULES, build_parser

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs"
sys.path.insert(0, str(DOCS / "_ext"))

from gcpfree_docs import commands, executed, schemas, validation

# the pages whose commands a reader copies: the tutorials, getting started, the README
COMMAND_PAGES = sorted((DOCS / "tutorials").glob("*.md")) + [DOCS / "getting-started.md",
                                                             REPO / "README.md"]
FENCE = re.compile(r"^```(bash|console|sh|shell)\s*$(.*?)^```\s*$", re.MULTILINE | re.DOTALL)


def gcpfree_lines(markdown: str) -> Iterator[list[str]]:
    """Each ``gcpfree`` command of the shell blocks of ``markdown``, as its argv after
    ``gcpfree`` (continuation lines joined, a ``$ `` prompt, ``VAR=value`` prefixes, a trailing
    ``&`` and comments dropped)."""
    for block in FENCE.finditer(markdown):
        text = block.group(2).replace("\\\n", " ")
        for line in text.splitlines():
            line = line.strip().removeprefix("$ ")
            words = shlex.split(line, comments=True)
            while words and re.fullmatch(r"[A-Z_][A-Z0-9_]*=\S*", words[0]):
                words = words[1:]
            if words and words[0] == "gcpfree":
                yield [w for w in words[1:] if w != "&"]


def parse_error(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str | None:
    """None when ``gcpfree ARGV`` parses with the real parser, else what it said."""
    try:
        build_parser().parse_args(argv)
    except SystemExit as exc:
        return capsys.readouterr().err.strip() or f"exit {exc.code}"
    return None


@pytest.mark.parametrize("page", COMMAND_PAGES, ids=lambda p: p.relative_to(REPO).as_posix())
def test_every_command_of_the_tutorials_parses(page: Path, capsys):
    found = list(gcpfree_lines(page.read_text()))
    if page.parent.name == "tutorials" and page.stem != "index":
        assert found, f"{page.name} runs no gcpfree command"
    bad = {shlex.join(["gcpfree", *a]): e for a in found if (e := parse_error(a, capsys))}
    assert not bad, bad


def test_the_command_check_catches_a_renamed_option(capsys):
    text = "```bash\ngcpfree orient --left L.tif --right R.tif \\\n    --srtm-folder DIR --out O\n```\n"
    (argv,) = gcpfree_lines(text)
    assert argv[-4:] == ["--srtm-folder", "DIR", "--out", "O"]
    assert "--srtm-folder" in parse_error(argv, capsys)


def _subparsers() -> dict[str, argparse.ArgumentParser]:
    return commands.subparsers(build_parser())


def test_every_command_has_a_page_with_every_option(tmp_path):
    names = commands.write_pages(tmp_path, DOCS / "reference" / "notes")
    assert names == list(COMMAND_MODULES)
    index = (tmp_path / "index.md").read_text()
    for name, parser in _subparsers().items():
        page = (tmp_path / f"{name}.md").read_text()
        assert page.startswith(f"# `gcpfree {name}`"), name
        assert f"]({name}.md)" in index, name
        missing = [s for s in commands.iter_option_strings(parser) if f"`{s}" not in page]
        assert not missing, (name, missing)
        notes = DOCS / "reference" / "notes" / f"{name}.md"
        assert (f"../notes/{name}.md" in page) == notes.exists(), name


def test_a_notes_file_of_no_command_fails_the_build(tmp_path):
    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "orient.md").write_text("# What it does\n")
    (notes / "orientate.md").write_text("# What it does\n")
    with pytest.raises(RuntimeError, match="orientate"):
        commands.write_pages(tmp_path / "out", notes)


def test_every_product_has_a_page_from_its_schema(tmp_path):
    slugs = schemas.write_pages(tmp_path, DOCS / "reference" / "notes" / "products")
    assert {s.split("-")[0] for s in slugs} >= {
        "report", "eval", "rel", "pair", "summary", "windows", "gcps"}
    layer = schemas.layer_schemas()
    for product in schemas.products(layer):
        page = (tmp_path / f"{product.slug}.md").read_text()
        schema, _ = schemas.schema_of(product, layer)
        if schema is None:
            assert "plain dict" in page, product.name
            continue
        assert "## Schema" in page, product.name
        for key in schema.get("properties", {}):
            assert f"| `{key}` |" in page, (product.name, key)


def test_the_dataclass_schema_follows_the_type_hints():
    from core.points import ControlPoint

    s = schemas.dataclass_schema(ControlPoint)
    assert s["properties"]["lon_deg"] == {"type": "number"}
    assert s["properties"]["image_points"] == {
        "type": "object", "additionalProperties": {"$ref": "#/$defs/ImagePoint"}}
    assert "source" not in s["required"] and "id" in s["required"]
    assert set(s["$defs"]["ImagePoint"]["properties"]) == {"col", "row"}


def test_the_speed_figures_are_read_from_the_bench_results():
    wall = validation.dsm_wall((validation.RESULTS / "dsm_wall.txt").read_text())
    assert wall["cars_s"] == 229.0 and wall["gcpfree_later_s"] < wall["gcpfree_first_s"]
    rounds = validation.pair_rounds((validation.RESULTS / "bench_pair_spot.txt").read_text())
    assert len(rounds) >= 4
    assert all(r["two_s"] < r["one_s"] for r in rounds)


def test_an_executed_block_shows_its_output_and_a_raising_one_fails(tmp_path):
    page = ("# P\n\n```{python-run}\nx = 6 * 7\nprint(x)\n```\n\ntext\n\n"
            "```{python-run}\nprint(x + 1)\nopen('figures/f.png', 'wb').write(b'png')\n```\n")
    out = executed.execute(page, tmp_path / "p.md", tmp_path / "generated" / "p")
    assert "```python\nx = 6 * 7\nprint(x)\n```\n\n```text\n42\n```" in out  # one namespace
    assert "```text\n43\n```" in out and "python-run" not in out
    assert (tmp_path / "generated" / "p" / "f.png").read_bytes() == b"png"
    with pytest.raises(executed.BlockError, match="block 2 raised"):
        executed.execute(page.replace("x + 1", "y"), tmp_path / "p.md", tmp_path / "g")


# ---------------------------------------------------------------------------- the built site


SPHINX = ("-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html")  # strict, as make docs


class SiteBuild:
    """The site's strict build in a child Python, started apart from the test that waits for
    it: when a session's collected tests use the site, tests/conftest.py starts it as
    collection ends, and the build (a minute, most of it the Python API tutorial's run) goes
    on beside the tests before these, on the second core."""

    def __init__(self, out: Path) -> None:
        self.out = out
        self.log = out.with_name(out.name + ".log")
        with self.log.open("w") as log:
            self.process = subprocess.Popen([sys.executable, *SPHINX, str(DOCS), str(out)],
                                            cwd=REPO, stdout=log, stderr=subprocess.STDOUT)
        atexit.register(self.stop)

    def wait(self) -> tuple[int, str]:
        """The build's exit status and what it printed."""
        return self.process.wait(), self.log.read_text()

    def stop(self) -> None:
        if self.process.poll() is None:  # the session ended before a test used the site
            self.process.kill()
            self.process.wait()
        shutil.rmtree(self.out.parent, ignore_errors=True)


_STARTED: list[SiteBuild] = []


def docs_extra_lacking() -> list[str]:
    return [m for m in ("sphinx", "myst_parser", "furo") if importlib.util.find_spec(m) is None]


def start_site_build() -> None:
    """Start the site's build now (once per session), for the fixture ``site`` to wait for."""
    if not _STARTED and not docs_extra_lacking():
        _STARTED.append(SiteBuild(Path(tempfile.mkdtemp(prefix="gcpfree-tests-site-")) / "site"))


@pytest.fixture(scope="session")
def site() -> Path:
    """The site built once, strictly (``-W``), as ``make docs`` builds it."""
    from tests.browser import unavailable

    if lacking := docs_extra_lacking():
        unavailable(f"the docs extra is not installed ({', '.join(lacking)}): "
                    "pip install -e '.[docs]'")
    start_site_build()  # unless collection started it
    returncode, printed = _STARTED[0].wait()
    assert returncode == 0, f"make docs fails:\n{printed}"
    return _STARTED[0].out


def pages(site: Path) -> list[Path]:
    return sorted(p for p in site.rglob("*.html")
                  if not p.relative_to(site).parts[0].startswith("_")
                  and p.name not in ("genindex.html", "search.html"))


def test_the_site_has_every_page(site):
    built = {p.relative_to(site).as_posix() for p in pages(site)}
    expected = {f"reference/commands/{n}.html" for n in COMMAND_MODULES}
    expected |= {f"reference/products/{p.slug}.html" for p in schemas.PRODUCTS}
    expected |= {f"tutorials/{p.stem}.html" for p in (DOCS / "tutorials").glob("*.md")}
    expected |= {"index.html", "getting-started.html", "validation/index.html",
                 "method/index.html", "changelog.html"}
    assert expected <= built, sorted(expected - built)


def test_the_python_api_tutorial_ran_in_the_build(site):
    """The page's code ran when the site was built: the flows' typed results printed, the
    tiny pair's check points oriented under 0.5 px, its DSM's figure made (the API's parts are
    tests/flows/test_api.py's)."""
    import html

    text = html.unescape((site / "tutorials" / "python-api.html").read_text())
    assert "SimulationSummary" in text and "OrientOutcome OrientReport" in text
    assert "EvaluationReport" in text and "dsm.png" in text
    rms = [float(v) for pair in re.findall(r"check points (\d+\.\d+) / (\d+\.\d+) px \(col",
                                           text) for v in pair]
    assert len(rms) == 4 and max(rms) < 0.5, rms
    assert (site / "_images" / "dsm.png").stat().st_size > 10_000


LOOK = """() => ({
  images: Array.from(document.images).map(i => ({
      src: i.getAttribute('src'), loaded: i.complete && i.naturalWidth > 0})),
  title: (document.querySelector('h1') || {}).textContent || '',
  pageWidth: document.documentElement.scrollWidth,
  windowWidth: window.innerWidth,
})"""
SHOTS = ("index.html", "validation/index.html", "reference/commands/orient.html",
         "tutorials/spot-dimap.html")


def _look_at(page: Any, html: Path) -> dict[str, Any]:
    page.goto(html.as_uri(), wait_until="load")
    return page.evaluate(LOOK)


@pytest.mark.slow
def test_the_site_renders_in_headless_chromium(site, tmp_path):
    """Every page in headless Chromium, on a desktop and on a phone: its title, every image
    loaded (the validation page's four figures among them), no page wider than the window,
    and nothing fetched from outside the site."""
    from tests.browser import chromium

    outside: list[str] = []
    seen: dict[str, dict[str, Any]] = {}
    wide: list[tuple[str, int]] = []
    with chromium() as browser:
        for width in (1280, 390):
            page = browser.new_page(viewport={"width": width, "height": 900})
            # every request not for a file (of the site) stopped and counted; the site's own
            # are matched out in the browser, not each sent here and let through
            page.route(re.compile(r"^(?!file:)"), lambda route: (
                outside.append(route.request.url), route.abort()))
            for html in pages(site):
                name = html.relative_to(site).as_posix()
                look = _look_at(page, html)
                seen.setdefault(name, look)
                if look["pageWidth"] > look["windowWidth"]:
                    wide.append((name, width))
                if width == 1280 and name in SHOTS:
                    shot = tmp_path / name.replace("/", "_").replace(".html", ".png")
                    page.screenshot(path=str(shot), full_page=True)
                    print(f"screenshot of {name}: {shot}")
            page.close()
    assert not outside, outside
    assert not wide, f"pages that scroll sideways (page, window width): {wide}"
    assert all(look["title"] for look in seen.values()), [n for n, v in seen.items()
                                                           if not v["title"]]
    unloaded = {n: [i["src"] for i in v["images"] if not i["loaded"]] for n, v in seen.items()}
    assert not any(unloaded.values()), {n: v for n, v in unloaded.items() if v}
    figures = {Path(i["src"]).name for i in seen["validation/index.html"]["images"]}
    assert {"relief_sweep.png", "predicted_vs_measured.png", "speed.png", "peers.png"} <= figures
