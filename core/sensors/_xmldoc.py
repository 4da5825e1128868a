"""Typed look-ups in a parsed XML metadata file (SPOT DIMAP, Sentinel-1 annotation): every
error names the file, the element and what is wrong with the file."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from core.errors import InputError


class XmlDoc:
    """``root`` of the file ``name``; ``damaged`` ends the message of a missing or unreadable
    element (what the file then is, e.g. "the DIMAP file is truncated or ...")."""

    def __init__(self, root: ET.Element, name: str, damaged: str) -> None:
        self.root, self.name, self.damaged = root, name, damaged

    def find(self, path: str, el: ET.Element | None = None) -> ET.Element:
        found = (self.root if el is None else el).find(path)
        if found is None:
            raise InputError(f"{self.name}: <{path}> is missing; {self.damaged}")
        return found

    def text(self, path: str, el: ET.Element | None = None) -> str:
        """The element's stripped text (empty when it has none)."""
        return (self.find(path, el).text or "").strip()

    def number(self, path: str, el: ET.Element | None = None) -> float:
        """The element's text as a finite number."""
        txt = self.text(path, el)
        try:
            v = float(txt)
        except (ValueError, OverflowError):
            raise InputError(f"{self.name}: <{path}> holds {txt[:40]!r}, not a number; "
                             f"{self.damaged}") from None
        if not np.isfinite(v):
            raise InputError(f"{self.name}: <{path}> is {txt[:40]!r}, not a finite number; "
                             f"{self.damaged}")
        return v
