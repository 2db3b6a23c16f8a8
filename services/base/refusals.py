"""Messages from a driver refused for a bad value: counted in a health counter, the
first one logged (a driver that keeps sending them would flood the log)."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any

from common.transport import Bus


class Refusals:
    """Refusals of ``what`` (the log's word for it), counted in the health counter
    ``name`` of ``bus``."""

    def __init__(self, bus: Bus, name: str, what: str) -> None:
        self.count = 0
        self._what = what
        self._log = logging.getLogger(bus.name)
        self._lock = threading.Lock()
        bus.report(name, lambda: self.count)

    def refuse(self, reason: object) -> None:
        """Count one; the first is logged with ``reason``."""
        with self._lock:
            self.count += 1
            first = self.count == 1
        if first:
            self._log.warning("%s refused (later ones only counted): %s", self._what, reason)

    def passed(self, convert: Callable[[Any], Any], m: Any, to: Callable[[Any], None]) -> None:
        """``to(convert(m))``, or the refusal counted when convert raises ValueError."""
        try:
            out = convert(m)
        except ValueError as exc:
            self.refuse(exc)
            return
        to(out)
