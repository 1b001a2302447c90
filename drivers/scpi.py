"""What the SCPI instruments insitu drives share: reading their error queue.

Example
-------
>>> replies = iter(['-222,"Data out of range"', '0,"No error"'])
>>> read_error_queue(lambda command: next(replies), "shaker", 12)
[(-222, 'Data out of range')]
"""

from __future__ import annotations

from collections.abc import Callable

from drivers.errors import ProtocolError

__all__ = ["read_error_queue"]


def read_error_queue(query: Callable[[str], str], name: str,
                     most: int) -> list[tuple[int, str]]:
    """Empty an instrument's error queue with ``SYST:ERR?`` (``query`` sends it and returns
    the reply): ``[(code, text), ...]``, oldest first, at most ``most`` of them (a queue that
    never empties is not waited for). ProtocolError (one line, naming ``name``) when a reply
    is not ``<code>,"<text>"``."""
    out: list[tuple[int, str]] = []
    for _ in range(most):
        reply = query("SYST:ERR?")
        code_s, _, text = reply.partition(",")
        try:
            code = int(code_s)
        except ValueError:
            raise ProtocolError(f"{name}: SYST:ERR? answered {reply!r}", name) from None
        if code == 0:
            break
        out.append((code, text.strip().strip('"')))
    return out
