"""A LAZ child (:mod:`tasks.io.laz_child`) that aborts, as lazrs does, after sending its first
chunk of points: ``tests/tasks/test_lidar_damage.py`` runs it in place of the real one to see a
crash in the middle of a stream. Not a test module (pytest collects ``test_*.py`` only)."""

from __future__ import annotations

import os
import sys
from typing import BinaryIO

from tasks.io import laz_child


class _AbortAfterFirstChunk:
    """Passes the frames on; once a chunk's points are written, flushes and aborts."""

    def __init__(self, out: BinaryIO) -> None:
        self.out = out
        self.writes = 0

    def write(self, data: bytes | memoryview) -> int:
        n = self.out.write(data)
        self.writes += 1
        if self.writes == 3:  # record size, first count, first points
            self.out.flush()
            os.abort()
        return n

    def flush(self) -> None:
        self.out.flush()


if __name__ == "__main__":
    path, offset, count, vlr, n, selection = sys.argv[1:]
    laz_child.decompress(path, int(offset), int(count), bytes.fromhex(vlr), int(n),
                         int(selection), _AbortAfterFirstChunk(sys.stdout.buffer))  # type: ignore[arg-type]
