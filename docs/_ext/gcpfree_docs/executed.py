"""Pages whose Python runs when the site is built, so that they show what the code does today.

A page's fenced blocks ````` ```{python-run} ````` are run in order, all in one fresh Python (a
child process with the repository on its path, in a temporary working folder, one namespace
for the page), and each is replaced by the code as a Python block followed by what it printed.
Figures the code saves under ``figures/`` in its working folder are copied to
``generated/<page>/`` beside the page (git ignores it) for the page to show. A block that raises
fails the build, with its traceback; the rest of the page is not run.

Sphinx reads a page again only when it changed: every page with such a block is marked
outdated at each build (``env-get-outdated``), so it runs every time the site is built.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[3]
MARK = "{python-run}"
FENCE = re.compile(r"^```\{python-run\}[^\n]*\n(.*?)^```[ \t]*$", re.MULTILINE | re.DOTALL)
TIMEOUT_S = 900

# the child: each block run in one namespace, its printed lines captured; JSON on stdout
RUNNER = r"""
import contextlib, io, json, sys, traceback
blocks = json.loads(sys.stdin.read())
namespace = {"__name__": "__main__"}
done = []
real_stdout = sys.stdout
for n, code in enumerate(blocks, start=1):
    out, err = io.StringIO(), io.StringIO()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            exec(compile(code, f"<block {n}>", "exec"), namespace)
    except BaseException:
        done.append({"out": out.getvalue(), "err": err.getvalue(),
                     "error": traceback.format_exc()})
        break
    done.append({"out": out.getvalue(), "err": err.getvalue(), "error": None})
real_stdout.write("\n@@gcpfree-docs@@" + json.dumps(done))
"""


class BlockError(RuntimeError):
    """A block of an executed page raised (or the child died): the build stops."""


def run_blocks(blocks: list[str], cwd: Path) -> list[dict[str, Any]]:
    """What each block printed (``out``), wrote to stderr (``err``) and raised (``error``),
    run in order in one child Python in ``cwd``."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]), "MPLBACKEND": "Agg"}
    done = subprocess.run([sys.executable, "-c", RUNNER], input=json.dumps(blocks), cwd=cwd,
                          env=env, capture_output=True, text=True, timeout=TIMEOUT_S,
                          check=False)
    _, sep, tail = done.stdout.rpartition("\n@@gcpfree-docs@@")
    if not sep:
        raise BlockError(f"the page's Python died (exit {done.returncode}): "
                         f"{(done.stderr or done.stdout)[-3000:]}")
    return json.loads(tail)


def _fenced(lang: str, text: str) -> str:
    ticks = "````" if "```" in text else "```"
    return f"{ticks}{lang}\n{text.rstrip()}\n{ticks}\n"


def execute(source: str, page: Path, figures_to: Path) -> str:
    """``source`` (the page's Markdown, from ``page``) with each python-run block replaced by
    its code and output; the figures saved under ``figures/`` copied into ``figures_to``."""
    blocks = [m.group(1) for m in FENCE.finditer(source)]
    if not blocks:
        return source
    with tempfile.TemporaryDirectory(prefix="gcpfree-docs-run-") as tmp:
        (Path(tmp) / "figures").mkdir()
        results = run_blocks(blocks, Path(tmp))
        for k, r in enumerate(results, start=1):
            if r["error"]:
                raise BlockError(f"{page}: python-run block {k} raised:\n{r['out']}{r['err']}"
                                 f"{r['error']}")
        if len(results) < len(blocks):
            raise BlockError(f"{page}: only {len(results)} of {len(blocks)} blocks ran")
        shutil.rmtree(figures_to, ignore_errors=True)
        made = sorted((Path(tmp) / "figures").iterdir())
        if made:
            figures_to.mkdir(parents=True)
            for f in made:
                shutil.copy2(f, figures_to / f.name)
    outputs = iter(results)

    def replaced(m: re.Match[str]) -> str:
        printed = next(outputs)["out"]
        return _fenced("python", m.group(1)) + ("\n" + _fenced("text", printed)
                                                if printed.strip() else "")

    return FENCE.sub(replaced, source)


def executed_pages(srcdir: Path) -> set[str]:
    """The docnames of the pages holding a python-run block."""
    return {p.relative_to(srcdir).with_suffix("").as_posix() for p in srcdir.rglob("*.md")
            if "_ext" not in p.parts and MARK in p.read_text(encoding="utf-8")}


def on_source_read(app: Any, docname: str, source: list[str]) -> None:
    if MARK not in source[0]:
        return
    page = Path(app.srcdir) / f"{docname}.md"
    figures = page.parent / "generated" / page.stem
    try:
        source[0] = execute(source[0], page, figures)
    except (BlockError, subprocess.TimeoutExpired) as exc:
        from sphinx.errors import ExtensionError

        raise ExtensionError(str(exc)) from None


def on_env_get_outdated(app: Any, env: Any, added: set[str], changed: set[str],
                        removed: set[str]) -> list[str]:
    return sorted(executed_pages(Path(app.srcdir)) - added - changed - removed)
