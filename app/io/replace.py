"""Files replaced whole: written beside their place, then moved onto it."""

from __future__ import annotations

import contextlib
import os
import secrets
from collections.abc import Iterator
from pathlib import Path

__all__ = ["replacing"]


@contextlib.contextmanager
def replacing(path: str | Path) -> Iterator[Path]:
    """A temporary file's path beside ``path``: write it in the block; it is moved onto
    ``path`` when the block ends, and removed if the block or the move fails (an old file
    at ``path`` stays whole). An OSError is raised naming ``path``, never the temporary
    file."""
    target = Path(path)
    tmp = target.with_name(f".{target.name}.{secrets.token_hex(4)}.part")
    try:
        yield tmp
        os.replace(tmp, target)
    except BaseException as err:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(err, OSError) and err.errno:
            raise type(err)(err.errno, os.strerror(err.errno), str(target)) from err
        raise
