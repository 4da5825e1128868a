"""Headless Chromium for the tests that look at a page as a user does (the run report, the
Prefect UI): Debian's ``chromium`` (``apt-get install chromium``; ``.ci/run`` installs it) driven
by Playwright from PyPI with ``executable_path`` (Playwright's own browser download is not
reachable here).

Without chromium (or playwright) the browser tests skip on a developer's machine and fail in
CI: ``.ci/run`` sets ``GCPFREE_REQUIRE_BROWSER=1``, so a browser it could not install is an
error there, not a silent skip.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Iterator
from typing import Any

import pytest

REQUIRE = "GCPFREE_REQUIRE_BROWSER"
# the machine's network is closed: without these Chromium floods it with refused connections
FLAGS = ("--disable-gpu", "--disable-quic", "--no-first-run", "--disable-background-networking",
         "--disable-component-update", "--disable-sync")
TIMEOUT_MS = 120_000  # a page on a loaded 2-core machine


def unavailable(reason: str) -> None:
    """Skip with ``reason``, or fail when the environment says the browser must be there."""
    if os.environ.get(REQUIRE, "") not in ("", "0"):
        pytest.fail(f"{reason} ({REQUIRE} is set: the browser tests must run here)")
    pytest.skip(reason)


def chromium_executable() -> str:
    for name in ("chromium", "chromium-browser"):
        if path := shutil.which(name):
            return path
    unavailable("chromium is not on PATH: `apt-get install chromium` (Debian) runs the browser "
                "tests; .ci/run installs it")
    raise AssertionError("unreachable")


@contextlib.contextmanager
def chromium() -> Iterator[Any]:
    """A headless Debian Chromium under Playwright (a ``playwright.sync_api.Browser``) with a
    fresh profile; closed on the way out."""
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        unavailable("playwright is not installed: pip install -e '.[test]'")
    executable = chromium_executable()
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=executable, args=list(FLAGS),
                                    timeout=TIMEOUT_MS)
        try:
            yield browser
        finally:
            browser.close()
