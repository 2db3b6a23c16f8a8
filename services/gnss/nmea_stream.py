"""A receiver's serial or TCP byte stream cut into NMEA sentences."""

from __future__ import annotations

from services.gnss.nmea import MAX_LEN


class LineSplitter:
    """Cuts a serial/TCP byte stream into candidate sentences (``$...`` without CR/LF).

    Resynchronises on the next ``$`` after garbage, a sentence cut short by another
    ``$``, or a run longer than ``max_len`` bytes; ``dropped_bytes`` counts what was
    skipped. It does not validate: pass each line to :func:`.nmea.parse_sentence`.
    """

    def __init__(self, max_len: int = MAX_LEN) -> None:
        self._buf = bytearray()
        self._max_len = max_len
        self.dropped_bytes = 0

    def _drop(self, n: int) -> None:
        # Line terminators between sentences are not garbage.
        chunk = self._buf[:n]
        self.dropped_bytes += n - chunk.count(b"\r") - chunk.count(b"\n")
        del self._buf[:n]

    def feed(self, data: bytes) -> list[bytes]:
        """Append ``data``; return the complete lines it finished, in order."""
        self._buf += data
        out: list[bytes] = []
        while True:
            start = self._buf.find(b"$")
            if start < 0:
                self._drop(len(self._buf))
                return out
            if start:
                self._drop(start)
            end = _find_eol(self._buf)
            restart = self._buf.find(b"$", 1, len(self._buf) if end < 0 else end)
            if restart > 0:  # a new sentence began before this one ended
                self._drop(restart)
                continue
            if end < 0:
                if len(self._buf) > self._max_len:
                    self._drop(len(self._buf))
                return out
            if end > self._max_len:
                self._drop(end)
                continue
            out.append(bytes(self._buf[:end]))
            del self._buf[: end + 1]


def _find_eol(buf: bytearray) -> int:
    cr, lf = buf.find(b"\r"), buf.find(b"\n")
    return lf if cr < 0 else cr if lf < 0 else min(cr, lf)
