"""The device end of a pseudo-terminal pair: a serial port a driver opens by path.

The mock keeps the master side; the driver opens :attr:`PtyPort.path` (the
slave side) like any serial port. The slave is put in raw mode so binary data
pass unchanged. The mock holds the slave open itself until the driver has
talked to it once; after that, when the driver closes the port, reads on the
master report a hang-up (:attr:`PtyPort.hung_up`), which is how a device sees
its host disconnect.
"""

from __future__ import annotations

import errno
import os
import select
import tty

__all__ = ["PtyPort"]


class PtyPort:
    """Master side of a pty pair, raw mode, non-blocking reads with a timeout."""

    def __init__(self) -> None:
        self._master, slave = os.openpty()
        tty.setraw(slave)
        self.path = os.ttyname(slave)
        self._slave: int | None = slave
        self.hung_up = False

    @property
    def closed(self) -> bool:
        return self._master < 0

    def read(self, timeout: float, max_bytes: int = 4096) -> bytes:
        """Bytes from the driver, or b"" after ``timeout`` s; sets :attr:`hung_up` on EIO."""
        if self._master < 0:
            return b""
        r, _, _ = select.select([self._master], [], [], timeout)
        if not r:
            return b""
        try:
            data = os.read(self._master, max_bytes)
        except OSError as err:
            if err.errno != errno.EIO:
                raise
            self.hung_up = True  # no process has the slave open any more
            return b""
        if data:
            self.hung_up = False
            self._release_slave()
        return data

    def write(self, data: bytes) -> bool:
        """Send bytes to the driver; False if nobody listens (or the port is closed)."""
        if self._master < 0:
            return False
        view = memoryview(data)
        try:
            while view:
                _, w, _ = select.select([], [self._master], [], 0.5)
                if not w:
                    return False  # driver not reading: the pty buffer is full
                n = os.write(self._master, view)
                view = view[n:]
        except OSError:
            return False
        return True

    def _release_slave(self) -> None:
        if self._slave is not None:
            os.close(self._slave)
            self._slave = None

    def close(self) -> None:
        """Close both ends (from the driver's point of view: the device is unplugged)."""
        self._release_slave()
        if self._master >= 0:
            os.close(self._master)
            self._master = -1
