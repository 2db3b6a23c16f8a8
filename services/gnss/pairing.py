"""The compass pairs the two antennas' fixes of one epoch. Each receiver is read by a
thread of its own, and one may run an epoch or more behind the other (serial
buffering, a slow link), so each side keeps its unpaired fixes for a while, not just
its latest."""

from __future__ import annotations

import threading

from common.messages.gnss import NavSatFix

# fixes an antenna keeps waiting for its partner's of the same epoch (at 5-10 Hz, about
# a second: a partner later than that is lost, not waited for)
UNPAIRED_KEPT = 8


class EpochPairer:
    """``add`` a fix of antenna 1 or 2 at its GGA epoch (time of day, s); returns the
    pair (antenna 1's, antenna 2's) when the other antenna's fix of that epoch is in.
    Thread-safe."""

    def __init__(self, kept: int = UNPAIRED_KEPT) -> None:
        self.kept = kept
        self._lock = threading.Lock()
        self._unpaired: dict[int, dict[float, NavSatFix]] = {1: {}, 2: {}}

    def add(self, epoch: float, fix: NavSatFix) -> tuple[NavSatFix, NavSatFix] | None:
        other = 2 if fix.antenna == 1 else 1
        with self._lock:
            mine, theirs = self._unpaired[fix.antenna], self._unpaired[other]
            match = theirs.get(epoch)
            if match is None:
                mine[epoch] = fix
                # the oldest by arrival goes first, not the smallest epoch: the time of
                # day starts again at midnight
                while len(mine) > self.kept:
                    del mine[next(iter(mine))]
                return None
            # the partner's fixes that came before this epoch's will find no pair now
            for e in list(theirs):
                del theirs[e]
                if e == epoch:
                    break
        return (fix, match) if fix.antenna == 1 else (match, fix)
