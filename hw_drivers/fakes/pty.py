"""Pseudo-terminals for the serial fakes: the driver opens the slave path like ``/dev/ttyUSB0``.

The fake device owns the master end. Raw mode on the slave keeps the line discipline from echoing or
translating bytes (a binary protocol would otherwise see ``\\r\\n`` rewritten and its own writes echoed).
"""

from __future__ import annotations

import contextlib
import os
import pty
import select
import termios
import tty


class PtyPair:
    """A pseudo-terminal pair: ``path`` for the driver, byte I/O on the master for the fake."""

    def __init__(self) -> None:
        self.master, self._slave = pty.openpty()
        tty.setraw(self._slave)
        attrs = termios.tcgetattr(self._slave)
        attrs[3] &= ~termios.ECHO  # lflag
        termios.tcsetattr(self._slave, termios.TCSANOW, attrs)
        self.path = os.ttyname(self._slave)
        self.closed = False

    def read(self, n: int = 4096, timeout: float = 0.05) -> bytes:
        """Up to ``n`` bytes the driver wrote, or b"" after ``timeout`` seconds."""
        if self.closed:
            return b""
        ready, _, _ = select.select([self.master], [], [], timeout)
        if not ready:
            return b""
        try:
            return os.read(self.master, n)
        except OSError:  # the driver side went away
            return b""

    def write(self, data: bytes) -> None:
        if not self.closed:
            os.write(self.master, data)

    def close(self) -> None:
        """Hang up: the driver's next read or write fails like an unplugged USB adapter."""
        if self.closed:
            return
        self.closed = True
        for fd in (self.master, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)
