"""JSON text to Python values with an error that names the document."""

from __future__ import annotations

import json
from typing import Any

from core.errors import InputError


def parse_json(text: str, what: str) -> Any:
    """``json.loads(text)``; InputError naming ``what`` (e.g. "scene.json") when it is not JSON."""
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(f"{what} is not valid JSON: {exc}") from exc
