"""Command-line subcommands: one module per command with ``add_parser(sub)`` and ``run(args)``,
registered by :mod:`flows.cli` (``COMMANDS``).

These modules import nothing heavy at import time (no Prefect, no Dask): the parser of every
command is built on each call of ``gcpfree``. ``run`` checks the inputs, then imports the
command's flow (a module-level ``@flow`` of ``flows/``) and runs it; ``info``, ``report`` and
``coregister`` run plain functions of ``tasks/``, no flow (see each module).
"""
