"""Command-line subcommands: one module per command with ``add_parser(sub)`` and ``run(args)``,
registered by :mod:`flows.cli` (``COMMANDS``).

These modules import nothing heavy at import time (no Prefect, no Dask): the parser of every
command is built on each call of ``gcpfree``. ``run`` checks the inputs, then imports the
command's flow (a module-level ``@flow`` of ``flows/``) and runs it, all inside
``flows._env.prefect_api()``: without a configured Prefect server, Prefect's temporary one starts
as the command starts and boots while the inputs are checked; ``api.ready()`` comes right before
the flow. ``info``, ``report`` and ``coregister`` run plain functions of ``tasks/``, no flow (see
each module).
"""
