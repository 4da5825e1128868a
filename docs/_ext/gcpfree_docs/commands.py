"""The command reference, generated from the ``gcpfree`` parser itself
(:func:`flows.cli.build_parser`, the registry :data:`flows.cli.COMMAND_MODULES`): one page per
command with its usage, every option (flags, values, default, help) as argparse states them,
the command module's docstring, and the hand-written notes of ``docs/reference/notes/NAME.md``
(what it writes, what it refuses, figures) when there are some.

Nothing here is typed by hand about an option: a new option, or a new command, shows up at the
next build; a notes file of no command fails the build.
"""

from __future__ import annotations

import argparse
import ast
import importlib
import inspect
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

WIDTH = 92  # the usage lines' width (argparse reads $COLUMNS)


@dataclass(frozen=True)
class Option:
    """One argument of a command as argparse holds it."""

    flags: str  # "--out OUT" or the positional's name
    values: str  # the choices, or ""
    default: str  # "" when none or irrelevant
    required: bool
    help: str


def subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    """The parser of each subcommand, in the order of ``gcpfree --help``."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    raise RuntimeError("gcpfree's parser has no subcommands")


def _summaries(parser: argparse.ArgumentParser) -> dict[str, str]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return {a.dest: a.help or "" for a in action._choices_actions}
    return {}


def options(parser: argparse.ArgumentParser) -> list[Option]:
    """Every argument of ``parser`` but ``--help``, with its help text expanded as argparse
    prints it (``%(default)s`` filled in)."""
    formatter = parser._get_formatter()
    out = []
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction):
            continue
        if action.option_strings:
            metavar = ""
            if action.nargs != 0:
                metavar = " " + formatter._format_args(action, action.dest.upper())
            flags = ", ".join(f"{s}{metavar}" for s in action.option_strings)
        else:
            flags = formatter._format_args(action, action.dest)
        values = " | ".join(str(c) for c in action.choices) if action.choices else ""
        default = ""
        if action.default not in (None, False, argparse.SUPPRESS) and action.nargs != 0:
            default = str(action.default)
        try:
            text = formatter._expand_help(action) if action.help else ""
        except (TypeError, ValueError, KeyError) as exc:  # `gcpfree CMD --help` fails too
            raise RuntimeError(f"{parser.prog} {'/'.join(action.option_strings)}: its help text "
                               f"does not format ({exc}); a literal % is written %%") from exc
        out.append(Option(flags, values, default, bool(action.required), " ".join(text.split())))
    return out


def usage(parser: argparse.ArgumentParser) -> str:
    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(WIDTH)
    try:
        text = parser.format_usage()
    finally:
        if old is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = old
    return text.removeprefix("usage: ").rstrip()


def module_docstring(module_name: str) -> str:
    """The command module's docstring, its reST roles made plain Markdown code."""
    module = importlib.import_module(module_name)
    source = inspect.getsource(module)
    text = ast.get_docstring(ast.parse(source)) or ""
    return rest_to_markdown(text)


def rest_to_markdown(text: str) -> str:
    """``literal`` -> `literal`; :func:`x.y` -> `x.y` (the roles of the code's docstrings)."""
    import re

    text = re.sub(r":(?:func|class|mod|meth|data|attr|exc):`~?([^`]+)`", r"`\1`", text)
    text = text.replace("``", "`")
    return text


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def page(name: str, parser: argparse.ArgumentParser, summary: str, module_name: str,
         notes: Path | None) -> str:
    lines = [f"# `gcpfree {name}`", "", f"{summary[:1].upper()}{summary[1:]}.", "",
             "```text", usage(parser), "```", ""]
    if parser.description:
        lines += [" ".join(parser.description.split()), ""]
    lines += ["## Options", ""]
    for opt in options(parser):  # a definition list: narrow screens keep the flags whole
        flags = ", ".join(f"`{f}`" for f in opt.flags.split(", "))
        lines.append(flags + (" (required)" if opt.required else ""))
        text = opt.help or "(no help text)"
        extra = [f"one of `{opt.values}`" if opt.values else "",
                 f"default `{opt.default}`" if opt.default else ""]
        extra = "; ".join(e for e in extra if e)
        lines += [f": {text}" + (f" ({extra})" if extra else ""), ""]
    lines += ["", "## In the code", "",
              f"`{module_name}` (`add_parser`, `run`), registered in `flows.cli.COMMAND_MODULES`.",
              "", module_docstring(module_name), ""]
    if notes is not None:
        lines += [f"```{{include}} ../notes/{notes.name}", ":heading-offset: 1", "```", ""]
    return "\n".join(lines)


def index_page(names: list[str], summaries: dict[str, str]) -> str:
    lines = ["# Commands", "",
             ("Every `gcpfree` subcommand, generated from the parser at build time "
             "(`flows.cli.build_parser`). `gcpfree --verbose COMMAND` shows Prefect's and Dask's "
             "logs; bad input is one line on stderr and exit status 2, before anything is "
             "written; exit status 1 means a run completed with failures (an archive pair)."), "",
             "| command | what it does |", "|---|---|"]
    lines += [f"| [`{n}`]({n}.md) | {_cell(summaries.get(n, ''))} |" for n in names]
    lines += ["", "```{toctree}", ":hidden:", "", *names, "```", ""]
    return "\n".join(lines)


def write_pages(out: Path, notes_dir: Path) -> list[str]:
    """The command pages into ``out`` (``index.md`` and one ``NAME.md`` per command); the
    names written. A notes file naming no command is an error."""
    from flows.cli import COMMAND_MODULES, build_parser

    parser = build_parser()
    subs = subparsers(parser)
    summaries = _summaries(parser)
    names = list(COMMAND_MODULES)
    if set(names) != set(subs):
        raise RuntimeError(f"registry {sorted(names)} and parser {sorted(subs)} differ")
    orphans = sorted(p.stem for p in notes_dir.glob("*.md") if p.stem not in subs)
    if orphans:
        raise RuntimeError(f"docs/reference/notes/ has notes of no command: {orphans}")
    out.mkdir(parents=True, exist_ok=True)
    for old in out.glob("*.md"):  # a command gone from the registry loses its page
        if old.stem not in subs and old.stem != "index":
            old.unlink()
    for name in names:
        notes = notes_dir / f"{name}.md"
        text = page(name, subs[name], summaries.get(name, ""), COMMAND_MODULES[name].__name__,
                    notes if notes.exists() else None)
        _write_if_changed(out / f"{name}.md", text)
    _write_if_changed(out / "index.md", index_page(names, summaries))
    return names


def _write_if_changed(path: Path, text: str) -> None:
    """Write ``text`` unless the file holds it already (Sphinx rebuilds what changed)."""
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


def iter_option_strings(parser: argparse.ArgumentParser) -> Iterator[str]:
    for action in parser._actions:
        if not isinstance(action, argparse._HelpAction):
            yield from action.option_strings
