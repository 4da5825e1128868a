"""Peer implementations the tests and benchmarks compare with, loaded when installed."""

from __future__ import annotations

import importlib
import importlib.util
import sys
import types


def rpcm_model_module() -> types.ModuleType | None:
    """``rpcm.rpc_model`` without ``rpcm/__init__.py`` (it imports srtm4, which does not build
    here, and geojson): through a bare package stub that skips that ``__init__``; None when
    rpcm is absent or its module does not import."""
    if "rpcm.rpc_model" in sys.modules:
        return sys.modules["rpcm.rpc_model"]
    spec = importlib.util.find_spec("rpcm")
    if spec is None or not spec.submodule_search_locations:
        return None
    if "rpcm" not in sys.modules:
        stub = types.ModuleType("rpcm")
        stub.__path__ = list(spec.submodule_search_locations)
        stub.__spec__ = spec
        sys.modules["rpcm"] = stub
    try:
        return importlib.import_module("rpcm.rpc_model")
    except ImportError:
        return None
