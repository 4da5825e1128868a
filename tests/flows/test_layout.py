"""One pattern for flows and commands, read from the source: every flow a module-level
``@flow`` in ``flows/``, no ``@task`` there, every subcommand a module in ``flows/commands/``
that the registry (``flows.cli.COMMANDS``) lists and that imports nothing heavy; and the pair's
inputs as one value (:class:`tasks.io.pair.PairInputs`)."""

from __future__ import annotations

import argparse
import ast
import subprocess
import sys
from pathlib import Path

import pytest

from core.errors import InputError
from tasks.io.pair import PairInputs

REPO = Path(__file__).resolve().parents[2]
FLOWS = REPO / "flows"


def _decorators(path: Path) -> list[tuple[str, int, bool]]:
    """(decorator name, line, at module level) of every ``flow``/``task`` decorator or call."""
    tree = ast.parse(path.read_text())
    top = {id(n) for n in tree.body}
    decorators = {id(d) for n in ast.walk(tree) for d in getattr(n, "decorator_list", [])}
    out = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for d in node.decorator_list:
                f = d.func if isinstance(d, ast.Call) else d
                name = f.id if isinstance(f, ast.Name) else getattr(f, "attr", "")
                if name in ("flow", "task", "cache"):
                    out.append((name, node.lineno, id(node) in top))
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and \
                node.func.id in ("flow", "task") and id(node) not in decorators:
            # flow(...)(fn): a flow built at run time
            out.append((node.func.id, node.lineno, False))
    return out


@pytest.mark.parametrize("path", sorted(FLOWS.rglob("*.py")), ids=lambda p: p.name)
def test_flows_are_module_level_and_tasks_live_in_tasks(path: Path):
    found = _decorators(path)
    assert not [f for f in found if f[0] != "flow" or not f[2]], found
    if path.parent.name == "commands" or path.name in ("cli.py", "_env.py"):
        assert not found  # commands import their flow inside run()


def test_every_command_is_a_module_of_flows_commands_and_cli_only_registers():
    from flows import cli

    for name, run in cli.COMMANDS.items():
        module = sys.modules[run.__module__]
        assert module.__name__ == f"flows.commands.{name.replace('-', '_')}", name
        assert callable(module.add_parser) and module.run is run
    tree = ast.parse((FLOWS / "cli.py").read_text())
    defined = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
    assert defined == {"build_parser", "main"}


def test_the_command_line_imports_nothing_heavy():
    """``gcpfree --help`` answers at once: the parser and every command module load no
    Prefect, Dask, NumPy or rasterio."""
    code = ("import sys, flows.cli; flows.cli.build_parser(); "
            "heavy = [m for m in ('prefect', 'dask', 'numpy', 'rasterio') if m in sys.modules]; "
            "print(heavy); sys.exit(bool(heavy))")
    proc = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True,
                          text=True, timeout=120, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_pair_inputs_from_the_options():
    ns = argparse.Namespace(left="l.tif", right="r.tif", left_model=None, right_model="r.json",
                            band=2, reference=None, reference_vertical="egm96",
                            srtm_dir="srtm", out="o")
    pair = PairInputs.from_args(ns)
    assert pair == PairInputs(Path("l.tif"), Path("r.tif"), None, Path("r.json"), 2,
                              reference_vertical="egm96", srtm_dir=Path("srtm"))
    assert pair.to_dict()["srtm_dir"] == "srtm" and pair.has_ground
    assert pair.with_models(Path("a"), Path("b")).left_model == Path("a")
    with pytest.raises(InputError, match="not both"):
        PairInputs("l", "r", reference="ref.tif", srtm_dir="srtm")
    with pytest.raises(InputError, match="--reference-vertical 'msl' unknown"):
        PairInputs("l", "r", reference_vertical="msl")
