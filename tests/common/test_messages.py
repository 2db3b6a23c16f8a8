"""Every message type on the bus round-trips through the wire codec, and bad bytes
are rejected with msgspec's errors rather than anything else."""

from __future__ import annotations

import msgspec
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from common import keys
from common.codec import decode, encode
from common.messages.core import Array, Message
from tests.strategies import strategy_for

WIRE_TYPES = sorted(
    {*keys.TOPICS.values(), *(r for _, r in keys.RPCS.values())}, key=lambda t: t.__name__
)
REQUEST_TYPES = [q for q, _ in keys.RPCS.values()]


@pytest.mark.parametrize("msg_type", WIRE_TYPES + REQUEST_TYPES, ids=str)
@settings(max_examples=30, deadline=None)
@given(data=st.data())
def test_round_trip(msg_type: object, data: st.DataObject) -> None:
    msg = data.draw(strategy_for(msgspec.inspect.type_info(msg_type)))
    assert decode(encode(msg), msg_type) == msg


@pytest.mark.parametrize("msg_type", WIRE_TYPES, ids=str)
def test_messages_are_frozen_and_stamped(msg_type: type) -> None:
    assert issubclass(msg_type, Message)
    assert msg_type.__struct_config__.frozen


def test_topic_keys_are_unique_and_namespaced() -> None:
    all_keys = list(keys.TOPICS) + list(keys.RPCS)
    assert len(all_keys) == len(set(all_keys))
    assert all(k.startswith(keys.PREFIX + "/") for k in all_keys)
    assert keys.GNSS_FIX.at(antenna=2).key == "phenorover/gnss/2/fix"


@settings(max_examples=50, deadline=None)
@given(
    hnp.arrays(
        dtype=st.sampled_from([np.float32, np.float64, np.int32, np.uint8, np.int64]),
        shape=hnp.array_shapes(min_dims=0, max_dims=3, max_side=5),
    )
)
def test_array_round_trip(a: np.ndarray) -> None:
    back = decode(encode(Array.of(a)), Array).numpy()
    assert back.shape == a.shape and back.dtype == a.dtype
    np.testing.assert_array_equal(back, a)


def test_array_rejects_inconsistent_data() -> None:
    with pytest.raises(ValueError, match="needs 12 bytes, got 8"):
        Array(dtype="<f4", shape=(3,), data=b"\0" * 8).numpy()
    with pytest.raises(ValueError, match="not a supported wire dtype"):
        Array(dtype="O", shape=(1,), data=b"\0" * 8).numpy()


def test_out_of_range_value_fails_decoding_with_the_field_named() -> None:
    from common.messages.base import Twist

    with pytest.raises(msgspec.ValidationError, match=r"linear_x"):
        decode(msgspec.msgpack.encode({"linear_x": 50.0, "angular_z": 0.0}), Twist)


def test_numpy_scalars_encode_as_numbers() -> None:
    from common.messages.nav import PoseEstimate

    msg = PoseEstimate(x=np.float64(1.5), y=np.float32(2.0), yaw=np.int64(0))  # type: ignore[arg-type]
    back = decode(encode(msg), PoseEstimate)
    assert (back.x, back.y, back.yaw) == (1.5, 2.0, 0)
