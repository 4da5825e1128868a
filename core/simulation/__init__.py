"""Scene simulation kernels: deterministic fields of ground coordinates and a seed.

Every function is a pure function of its coordinates (ground metres, image
rows/cols or times), a seed and a configuration, so a Dask tile computes the
same bytes as the whole scene would. See :mod:`core.simulation.hashing`.

Modules: ``hashing`` (counter-based random numbers), ``fields`` (noise), ``landcover``,
``surface`` (the truth surface), ``lidar``, ``render`` (radiance and digital numbers),
``raycast`` (lines of sight on the truth DSM), ``jitter``, ``scene`` (presets, truth and
delivered models, the scene record), ``checkpoints``.
"""
