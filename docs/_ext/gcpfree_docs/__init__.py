"""The site's generated pages, made when the build starts (``builder-inited``), before Sphinx
reads the sources: the command reference from the ``gcpfree`` parser
(:mod:`gcpfree_docs.commands`), the products' schemas (:mod:`gcpfree_docs.schemas`), and the
validation tables and figures from ``bench/results/`` (:mod:`gcpfree_docs.validation`); and
the pages whose Python runs at each build, their output embedded (:mod:`gcpfree_docs.executed`).

Each writes only into its own folder, which git ignores: ``docs/reference/commands/``,
``docs/reference/products/``, ``docs/validation/generated/``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from gcpfree_docs import commands, executed, schemas, validation

DOCS = Path(__file__).resolve().parents[2]


def generate(docs: Path = DOCS) -> dict[str, list[str]]:
    """Every generated page, snippet and figure under ``docs``; what was written."""
    return {
        "commands": commands.write_pages(docs / "reference" / "commands",
                                         docs / "reference" / "notes"),
        "products": schemas.write_pages(docs / "reference" / "products",
                                        docs / "reference" / "notes" / "products"),
        "validation": validation.write_all(docs / "validation" / "generated"),
    }


def _on_builder_inited(app: Any) -> None:
    generate(Path(app.srcdir))


def setup(app: Any) -> dict[str, Any]:
    app.connect("builder-inited", _on_builder_inited)
    app.connect("source-read", executed.on_source_read)
    app.connect("env-get-outdated", executed.on_env_get_outdated)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
