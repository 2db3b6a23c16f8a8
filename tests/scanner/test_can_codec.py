"""Every FARO frame type round-trips through faro.dbc; bad frames fail clearly."""

from __future__ import annotations

import contextlib
from pathlib import Path

import can
import pytest
from hypothesis import given
from hypothesis import strategies as st

from services.scanner.can_codec import (
    DBC_PATH,
    Ack,
    AckResult,
    CanDecodeError,
    CanEncodeError,
    EndScan,
    FaroCodec,
    Frame,
    Inclinometer,
    InitiateScan,
    RecordPause,
    ScanProfile,
    ScanState,
    Status,
    default_codec,
)

u16 = st.integers(0, 65535)
profiles = st.builds(ScanProfile, resolution_index=st.integers(0, 8), quality=st.integers(1, 8))
# Inclinometer angles on the DBC's 0.001 deg grid.
milli = st.integers(-30_000, 30_000).map(lambda m: m / 1000)

frames = st.one_of(
    st.builds(InitiateScan, scan_id=u16, profile=profiles),
    st.builds(RecordPause, pause=st.booleans()),
    st.builds(EndScan, scan_id=u16),
    st.builds(Ack, command_id=st.integers(0, 0x7FF), result=st.sampled_from(AckResult)),
    st.builds(
        Status,
        state=st.sampled_from(ScanState),
        progress_pct=st.integers(0, 100),
        error_code=u16,
        scan_id=u16,
    ),
    st.builds(Inclinometer, pitch_deg=milli, roll_deg=milli, scan_id=u16),
)


@given(frames)
def test_round_trip(frame: Frame) -> None:
    codec = default_codec()
    msg = codec.encode(frame)
    assert not msg.is_extended_id and msg.arbitration_id <= 0x7FF
    assert msg.dlc == len(msg.data) <= 8
    back = codec.decode(msg)
    if isinstance(frame, Inclinometer):
        assert isinstance(back, Inclinometer)
        assert back.pitch_deg == pytest.approx(frame.pitch_deg, abs=1e-9)
        assert back.roll_deg == pytest.approx(frame.roll_deg, abs=1e-9)
        assert back.scan_id == frame.scan_id
    else:
        assert back == frame


def test_ids_come_from_the_dbc() -> None:
    codec = default_codec()
    ids = {k: codec.frame_id(k) for k in (InitiateScan, RecordPause, EndScan, Ack, Status)}
    assert len(set(ids.values())) == len(ids)
    assert codec.encode(EndScan(scan_id=1)).arbitration_id == ids[EndScan]


def frame(fid: int, data: bytes, **kw: bool) -> can.Message:
    return can.Message(arbitration_id=fid, data=data, is_extended_id=kw.pop("ext", False), **kw)


STATUS = default_codec().frame_id(Status)
ACK = default_codec().frame_id(Ack)


@pytest.mark.parametrize(
    ("msg", "words"),
    [
        (frame(0x7AB, bytes(6)), "0x7AB: unknown id"),
        (frame(STATUS, bytes(3)), "DLC 3, expected 6"),
        (frame(STATUS, bytes(8)), "DLC 8, expected 6"),
        (frame(STATUS, bytes(6), ext=True), "extended id"),
        (frame(STATUS, bytes([9, 0, 0, 0, 0, 0])), "State=9 outside"),
        (frame(STATUS, bytes([1, 101, 0, 0, 0, 0])), "Progress=101 outside"),
        (frame(ACK, bytes([0, 1, 9])), "Result=9 outside"),
        (frame(STATUS, b"", is_error_frame=True), "error frame"),
        (frame(STATUS, b"", is_remote_frame=True), "remote frame"),
    ],
)
def test_bad_frames(msg: can.Message, words: str) -> None:
    with pytest.raises(CanDecodeError, match=words) as info:
        default_codec().decode(msg)
    assert "\n" not in str(info.value)
    width = 8 if msg.is_extended_id else 3
    assert f"0x{msg.arbitration_id:0{width}X}" in str(info.value)


@pytest.mark.parametrize(
    "bad",
    [
        Status(state=ScanState.SCANNING, progress_pct=150),
        InitiateScan(scan_id=70_000),
        InitiateScan(scan_id=1, profile=ScanProfile(resolution_index=9)),
        Inclinometer(pitch_deg=45.0, roll_deg=0.0),
    ],
)
def test_out_of_range_fields_do_not_encode(bad: Frame) -> None:
    with pytest.raises(CanEncodeError):
        default_codec().encode(bad)


def test_edited_dbc_is_checked(tmp_path: Path) -> None:
    text = DBC_PATH.read_text().replace(" SG_ Progress :", " SG_ Percent :")
    (tmp_path / "faro.dbc").write_text(text)
    with pytest.raises(ValueError, match=r"Status lacks signals \['Progress'\]"):
        FaroCodec(tmp_path / "faro.dbc")
    moved = DBC_PATH.read_text().replace("BO_ 385 Status", "BO_ 1000 Status")
    moved = moved.replace("CM_ SG_ 385", "CM_ SG_ 1000").replace("VAL_ 385", "VAL_ 1000")
    (tmp_path / "moved.dbc").write_text(moved)
    codec = FaroCodec(tmp_path / "moved.dbc")
    assert codec.frame_id(Status) == 1000
    back = codec.decode(codec.encode(Status(state=ScanState.DONE, progress_pct=100)))
    assert back == Status(state=ScanState.DONE, progress_pct=100)


@given(
    fid=st.integers(0, 0x7FF),
    data=st.binary(max_size=8),
    ext=st.booleans(),
)
def test_arbitrary_frames_decode_or_raise_can_decode_error(
    fid: int, data: bytes, ext: bool
) -> None:
    codec = default_codec()
    ids = [codec.frame_id(k) for k in (InitiateScan, RecordPause, EndScan, Ack, Status)]
    fid = fid if fid % 2 else ids[fid % len(ids)]  # half the cases hit a known id
    with contextlib.suppress(CanDecodeError):
        codec.decode(frame(fid, data, ext=ext))
