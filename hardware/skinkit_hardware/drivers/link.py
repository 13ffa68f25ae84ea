"""What the serial and CAN transports share: the heartbeat thread, the hello handshake and
closing the link without masking the error that made the host close it."""

from __future__ import annotations

import threading
import time
from typing import Any

from skinkit_hardware import faults as F


class LinkTransport:
    """Base of a host-side transport. Subclasses provide ``send``, ``receive``, ``info`` and
    ``_close_link``, and call :meth:`_start_heartbeat` from their constructor.

    Heartbeats go out with every ``receive`` and, when enabled, from a background thread every
    ``heartbeat_s`` [s] so that holding between runs does not trip the device's watchdog.
    """

    info: dict[str, Any]

    def _start_heartbeat(self, enabled: bool, heartbeat_s: float, thread_name: str) -> None:
        self.lock = threading.Lock()
        self.heartbeat_s = heartbeat_s
        self.last_sent = 0.0
        self.stats: dict[str, Any] = {}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        if enabled:
            self._thread = threading.Thread(target=self._beat, name=thread_name, daemon=True)
            self._thread.start()

    def _beat(self) -> None:
        while not self._stop.wait(self.heartbeat_s):
            try:
                self.send("heartbeat")
            except F.DeviceFault:
                return

    def send(self, command: str, **args: Any) -> None:  # pragma: no cover - abstract
        """Send one host ``command`` with its ``args`` to the device."""
        raise NotImplementedError

    def receive(self, timeout_s: float) -> Any:  # pragma: no cover - abstract
        """``(samples (n, 15), events)`` received within ``timeout_s`` [s]."""
        raise NotImplementedError

    def _close_link(self) -> None:  # pragma: no cover - abstract
        raise NotImplementedError

    def handshake(self, no_answer: str, timeout_s: float = 3.0) -> None:
        """Say hello and wait up to ``timeout_s`` [s] for the device's info; close the link and
        raise :class:`DeviceFault` with message ``no_answer`` when none comes."""
        self.send("hello")
        t_end = time.monotonic() + timeout_s
        while not self.info and time.monotonic() < t_end:
            self.receive(0.05)
        if not self.info:
            self.close()
            raise F.DeviceFault(no_answer)

    def close(self) -> None:
        """Stop the heartbeat and close the link (errors of a dead link are ignored)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(1.0)
        try:
            self._close_link()
        except Exception:  # noqa: BLE001 - closing a dead link must not mask the real error
            pass
