"""LAZ decompression in a child process: ``python -P -m tasks.io.laz_child PATH OFFSET COUNT VLR
N SELECTION``.

lazrs, laspy's LAZ decoder, is Rust. On some damaged files it does not raise: a chunk table
whose count or offsets were damaged makes it allocate tens of gigabytes and abort the whole
process (SIGABRT), or panic (pyo3's ``PanicException``, a ``BaseException``). So gcpfree never
decompresses a LAZ in its own process: :func:`tasks.io.lidar.lidar_chunks` runs this module,
which imports only ``lazrs`` (laspy would add 0.6 s of imports), and reads the raw point
records from its standard output in frames of little-endian int64 words:

- first the size in bytes of one point record;
- ``n > 0`` then ``n`` records: ``N`` points at a time (the last frame holds the rest);
- ``0``: the end, all ``COUNT`` points sent; exit status 0;
- ``-1``, then the length and the UTF-8 text of the error lazrs raised; exit status 1.

A crash shows as the pipe closing before the end frame. The pipe blocks while the parent is
busy, so each side holds one chunk at most. ``N = 0`` only checks the file: it opens the decoder
(which reads the whole chunk table) and decodes one point.

The arguments come from the header the parent has read (laspy): the offset of the point data,
the point count, the LASzip VLR's payload in hex, and ``SELECTION``, the layers to decompress
(``lazrs.DecompressionSelection`` bits; point formats 6-10 skip the others, 0-5 ignore it).
"""

from __future__ import annotations

import struct
import sys
from typing import BinaryIO

import lazrs

WORD = struct.Struct("<q")
END = 0
ERROR = -1


def _send(out: BinaryIO, *words: int) -> None:
    out.write(b"".join(WORD.pack(w) for w in words))


def decompress(path: str, offset: int, count: int, vlr: bytes, n: int, selection: int,
               out: BinaryIO) -> None:
    """Write the frames of the file's ``count`` points to ``out``, ``n`` at a time (``n = 0``:
    check the chunk table and the first point only); lazrs errors propagate."""
    size = lazrs.LazVlr(vlr).item_size()
    _send(out, size)
    with open(path, "rb") as f:
        f.seek(offset)
        dec = lazrs.ParLasZipDecompressor(f, vlr, lazrs.DecompressionSelection(selection))
        if n == 0:
            if count:
                dec.decompress_many(bytearray(size))
        else:
            buf = bytearray(min(n, count) * size)
            sent = 0
            while sent < count:
                k = min(n, count - sent)
                view = memoryview(buf)[: k * size]
                dec.decompress_many(view)
                _send(out, k)
                out.write(view)
                sent += k
    _send(out, END)


def main(argv: list[str]) -> int:
    out = sys.stdout.buffer
    try:
        path, offset, count, vlr, n, selection = argv
        decompress(path, int(offset), int(count), bytes.fromhex(vlr), int(n), int(selection),
                   out)
    except BrokenPipeError:  # the parent stopped reading (it had what it wanted, or failed)
        return 1
    except BaseException as exc:  # noqa: BLE001 - lazrs.LazrsError, pyo3's PanicException
        text = " ".join(str(exc).split()) or type(exc).__name__
        if not isinstance(exc, (lazrs.LazrsError, ValueError, OSError)):
            text = f"{type(exc).__name__}: {text}"  # a panic: say so
        data = text[:300].encode("utf-8", "replace")
        try:
            _send(out, ERROR, len(data))
            out.write(data)
            out.flush()
        except BrokenPipeError:
            pass
        return 1
    out.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
