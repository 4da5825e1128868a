"""JSON text to Python values with an error that names the document."""

from __future__ import annotations

import json
from typing import Any

from core.errors import InputError


def parse_json(text: str, what: str) -> Any:
    """``json.loads(text)``; InputError naming ``what`` (e.g. "scene.json") when it is not JSON,
    nests deeper than Python can follow or holds an integer longer than Python converts."""
    try:
        return json.loads(text)
    except RecursionError:
        raise InputError(f"{what} is not valid JSON: nested too deeply") from None
    except ValueError as exc:  # JSONDecodeError, and integers over 4300 digits
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InputError(f"{what} is not valid JSON: {first}") from None
