"""Command-line subcommands: one module per command with ``add_parser(sub)`` and ``run(args)``.

These modules import nothing heavy at import time (no Prefect, no Dask): the parser of every
command is built on each call of ``gcpfree``, and ``gcpfree info`` answers without Prefect.
``run`` checks the inputs, then imports and runs the command's flow.
"""
