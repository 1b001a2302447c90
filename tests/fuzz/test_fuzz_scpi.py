"""The SCPI shaker driver on any replies: a value, or the driver's own DeviceError, nothing else."""

from __future__ import annotations

import math

from _fuzz import FUZZ
from hypothesis import given
from hypothesis import strategies as st

from drivers.errors import DeviceError, DeviceTimeoutError
from drivers.shaker_scpi import ScpiShaker


class _Replies:
    """Stands in for the serial link: every query is answered with the next fuzzed line."""

    def __init__(self, replies: list[bytes]) -> None:
        self.replies = replies

    def write(self, data: bytes) -> None:
        pass

    def readline(self, timeout: float, terminator: bytes = b"\n") -> bytes:
        if not self.replies or not self.replies[0].endswith(terminator):
            raise DeviceTimeoutError("sh: no reply within 0.5 s", "sh")  # as the link does
        return self.replies.pop(0)


reply = (st.binary(max_size=40) | st.from_regex(rb"\A[-+]?\d{0,4}(,\"[ -~]{0,20}\")?\Z")
         | st.sampled_from([b"0,\"No error\"", b"1", b"0", b"nan", b"1e999", b"-101,"])
         ).map(lambda b: b + b"\n") | st.binary(max_size=20)


@FUZZ
@given(st.lists(reply, max_size=12), st.sampled_from(["errors", "level", "on", "command"]))
def test_any_reply(replies: list[bytes], what: str) -> None:
    sh = ScpiShaker("sh", "loop://", heartbeat=0.0)
    sh._link = _Replies(list(replies))  # type: ignore[assignment]
    try:
        if what == "errors":
            errs = sh.errors()
            assert all(isinstance(c, int) and isinstance(t, str) for c, t in errs)
        elif what == "level":
            assert isinstance(sh.output_level(), float) or math.isnan(sh.output_level())
        elif what == "on":
            assert isinstance(sh.output_is_on(), bool)
        else:
            sh.command("OUTP:LEV 0.5")
    except DeviceError as err:
        assert str(err) and "\n" not in str(err)
