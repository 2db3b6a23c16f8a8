"""The compass pairs the antennas' fixes by epoch, whichever reader runs behind."""

from __future__ import annotations

from common.messages.gnss import FixType, NavSatFix
from services.gnss.pairing import EpochPairer


def fix(antenna: int, epoch: float) -> NavSatFix:
    # the epoch rides in the altitude, so a pair can be checked for its epoch
    return NavSatFix(
        antenna=antenna, latitude=33.7, longitude=-83.3, altitude=epoch, fix_type=FixType.FIX
    )


def epochs(pair: tuple[NavSatFix, NavSatFix] | None) -> tuple[float, float] | None:
    return None if pair is None else (pair[0].altitude, pair[1].altitude)


def test_a_reader_two_epochs_behind_still_pairs_every_epoch() -> None:
    p = EpochPairer()
    got = []
    for k in range(10):  # antenna 1 runs two epochs ahead of antenna 2
        got.append(epochs(p.add(k * 0.2, fix(1, k * 0.2))))
        if k >= 2:
            e = (k - 2) * 0.2
            got.append(epochs(p.add(e, fix(2, e))))
    pairs = [g for g in got if g is not None]
    assert pairs == [((k * 0.2), (k * 0.2)) for k in range(8)]


def test_antenna_order_and_a_lost_fix() -> None:
    p = EpochPairer()
    assert p.add(1.0, fix(2, 1.0)) is None
    assert epochs(p.add(1.0, fix(1, 1.0))) == (1.0, 1.0)
    assert p.add(1.2, fix(1, 1.2)) is None  # antenna 2's 1.2 is lost
    assert p.add(1.4, fix(1, 1.4)) is None
    pair = p.add(1.4, fix(2, 1.4))
    assert pair is not None and (pair[0].antenna, pair[1].antenna) == (1, 2)


def test_pairs_go_on_across_midnight() -> None:
    p = EpochPairer(kept=3)
    # antenna 1 a whole second ahead just before midnight: its fixes left unpaired
    for e in (86399.0, 86399.2, 86399.4, 86399.6, 86399.8):
        p.add(e, fix(1, e))
    for e in (0.0, 0.2, 0.4):  # the time of day starts again
        assert p.add(e, fix(2, e)) is None
        assert epochs(p.add(e, fix(1, e))) == (e, e)
