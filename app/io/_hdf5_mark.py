"""Clearing HDF5's "open for writing" mark, as HDF5's ``h5clear -s`` does, without its tools.

A file in the latest format (superblock version 2 or 3) carries file-consistency flags in its
superblock: set while a writer has it open, cleared when the writer closes it. A writer
killed while it held the file (``kill -9`` during a record's few milliseconds of writing)
leaves them set, and HDF5 then refuses every open ("file is already open for write"), SWMR
readers too unless the writer had switched SWMR on. Clearing them (byte 11 of the
superblock) and writing the superblock's checksum again (Bob Jenkins' lookup3 ``hashlittle``
over the bytes before it, as HDF5 computes it) makes the file open again; what was written
is then read as it is.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["clear_write_mark", "lookup3"]

_SIGNATURE = b"\x89HDF\r\n\x1a\n"
_M = 0xFFFFFFFF


def _rot(x: int, k: int) -> int:
    return ((x << k) | (x >> (32 - k))) & _M


def lookup3(data: bytes, initval: int = 0) -> int:
    """Bob Jenkins' lookup3 ``hashlittle`` of ``data`` (HDF5's metadata checksum)."""
    n = len(data)
    a = b = c = (0xDEADBEEF + n + initval) & _M
    i = 0
    while n - i > 12:
        a = (a + int.from_bytes(data[i:i + 4], "little")) & _M
        b = (b + int.from_bytes(data[i + 4:i + 8], "little")) & _M
        c = (c + int.from_bytes(data[i + 8:i + 12], "little")) & _M
        a = (a - c) & _M ^ _rot(c, 4)
        c = (c + b) & _M
        b = (b - a) & _M ^ _rot(a, 6)
        a = (a + c) & _M
        c = (c - b) & _M ^ _rot(b, 8)
        b = (b + a) & _M
        a = (a - c) & _M ^ _rot(c, 16)
        c = (c + b) & _M
        b = (b - a) & _M ^ _rot(a, 19)
        a = (a + c) & _M
        c = (c - b) & _M ^ _rot(b, 4)
        b = (b + a) & _M
        i += 12
    if n == i:
        return c
    tail = data[i:] + bytes(12 - (n - i))
    a = (a + int.from_bytes(tail[0:4], "little")) & _M
    b = (b + int.from_bytes(tail[4:8], "little")) & _M
    c = (c + int.from_bytes(tail[8:12], "little")) & _M
    c = (c ^ b) - _rot(b, 14) & _M
    a = (a ^ c) - _rot(c, 11) & _M
    b = (b ^ a) - _rot(a, 25) & _M
    c = (c ^ b) - _rot(b, 16) & _M
    a = (a ^ c) - _rot(c, 4) & _M
    b = (b ^ a) - _rot(a, 14) & _M
    c = (c ^ b) - _rot(b, 24) & _M
    return c


def clear_write_mark(path: str | Path) -> bool:
    """Clear the file-consistency flags of ``path``'s superblock; True if they were set.

    Only a superblock at the start of the file, of version 2 or 3, whose checksum verifies,
    is changed (5 bytes, written in place and synced); anything else is left alone (False).
    """
    with open(path, "r+b") as fh:
        head = fh.read(48)
        if len(head) < 12 or head[:8] != _SIGNATURE or head[8] not in (2, 3) or head[11] == 0:
            return False
        end = 12 + 4 * head[9]  # four addresses of size-of-offsets bytes each
        if len(head) < end + 4 or int.from_bytes(head[end:end + 4], "little") != lookup3(
                head[:end]):
            return False
        cleared = head[:11] + b"\0" + head[12:end]
        fh.seek(0)
        fh.write(cleared + lookup3(cleared).to_bytes(4, "little"))
        fh.flush()
        os.fsync(fh.fileno())
    return True
