"""The drivers' exception tree.

Every error a driver raises is a :class:`DeviceError`; the subclasses say what
kind of failure it was, and mix in the stdlib class a caller may already catch
(``DeviceTimeoutError`` is a ``TimeoutError``). Low-level errors are chained
with ``raise ... from err``.

Example
-------
>>> try:
...     raise DeviceTimeoutError("hammer: no frame for 0.5 s", device="hammer")
... except TimeoutError as err:
...     print(err.device)
hammer
"""

from __future__ import annotations

__all__ = [
    "DeviceError",
    "DeviceInitializationError",
    "DeviceNotAvailableError",
    "DeviceTimeoutError",
    "ProtocolError",
    "SyncError",
    "one_line",
]


class DeviceError(Exception):
    """Base of every driver error.

    Parameters
    ----------
    message : str
        One line saying what failed and, where possible, what to do.
    device : str, optional
        Name of the device (from the station file) the error is about.
    """

    def __init__(self, message: str, device: str | None = None) -> None:
        super().__init__(message)
        self.device = device


class DeviceNotAvailableError(DeviceError):
    """The device or its transport is missing, unplugged or already in use."""


class DeviceInitializationError(DeviceError):
    """The device answered but could not be configured (bad identity, refused setting)."""


class DeviceTimeoutError(DeviceError, TimeoutError):
    """The device did not answer or stopped streaming within the allowed time."""


class ProtocolError(DeviceError):
    """The device sent something the protocol does not allow (bad frame, bad reply)."""


class SyncError(DeviceError):
    """Streams from devices on separate clocks cannot be aligned; the run is refused."""


def one_line(text: str) -> str:
    """``text`` with its non-printable characters escaped (a key named ``"\\n"`` in a TOML
    file, say), so that an error message stays one line."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
