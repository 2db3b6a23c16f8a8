"""ROS 2 over Zenoh as rmw_zenoh speaks it: key expressions, liveliness tokens, QoS
strings, GIDs, the per-message attachment and the type names and hashes. Pure: no I/O.

Topics only: publishers and subscriptions with their liveliness tokens. ROS 2 services
(``SS``/``SC`` tokens, Zenoh queryables) and actions are not spoken.

Supported peers: **rmw_zenoh_cpp 0.2.4 and later on Jazzy, 0.6.x on Kilted and 0.6.0
to 0.12.0 on Rolling** (Zenoh 1.x); for the types of :mod:`services.base.ros2.types` their
attachment, tokens, keys and GIDs are the same. Read from ros2/rmw_zenoh as bloom
released it (ros2-gbp/rmw_zenoh-release, tags ``release/<distro>/rmw_zenoh_cpp/
<version>-1``, which hold the package directory ``rmw_zenoh_cpp/``):

- ros2/rmw_zenoh ``rmw_zenoh_cpp/src/detail/liveliness_utils.cpp`` at 0.2.10: the
  token layout (``KeyexprIndex``), the QoS string (``qos_to_keyexpr``),
  ``mangle_name`` ('/' -> '%'), the data key (``TopicInfo``: ``<domain>/<topic without
  outer slashes>/<type>/<hash>``) and the GID: ``Entity``'s constructor hashes the
  whole token with ``simplified_XXH3_128bits`` (``simplified_xxhash3.cpp``: xxHash's
  XXH3-128, default seed and secret) and memcpy's ``low64`` then ``high64`` into the
  16 bytes in native order, little-endian on every platform ROS 2 ships for. A peer
  hashes the tokens it sees the same way (``graph_cache.cpp``), so :func:`gid_of`'s
  GIDs, which our attachments carry as the publisher GID, are the ones ``ros2 topic
  info -v`` shows. Rolling 0.12.0 appends an optional part to the tokens of
  ``Buffer`` types only, none of ours;
- ros2/rmw_zenoh ``rmw_zenoh_cpp/src/detail/attachment_helpers.cpp`` at 0.2.4 to
  0.2.10 (Kilted 0.6.0 to 0.6.7, Rolling 0.6.0 to 0.12.0 alike):
  ``AttachmentData::serialize_to_zbytes``, a zenoh-ext Serializer fed int64 sequence
  number, int64 source timestamp and the ``std::array<uint8_t, 16>`` GID; zenoh-cpp's
  ``include/zenoh/api/ext/serialization.hxx`` writes a std::array as a sequence
  (LEB128 length, then the bytes), so the attachment is 33 bytes:
  ``<q <q 0x10 gid[16]``;
- ros2/rmw_zenoh ``rmw_zenoh_cpp/src/detail/rmw_publisher_data.cpp`` at 0.2.10:
  sequence numbers start at 1, the source timestamp is the system clock in ns, node
  and entity ids come from one counter per context (session);
- ros2/rmw_zenoh ``rmw_zenoh_cpp/src/detail/qos.cpp`` at 0.2.10: the defaults a QoS
  string leaves empty (reliable, volatile, keep-last 42, infinite durations);
- ros2/rmw_zenoh ``rmw_zenoh_cpp/src/detail/type_support_common.cpp`` at 0.2.10: type
  names ``pkg::msg::dds_::Type_``.

Jazzy 0.2.0 to 0.2.3 (and Rolling 0.3.0 to 0.5.0) lay out keys, tokens and GIDs the
same way (0.2.0 to 0.2.2 with transient-local as the QoS string's default durability)
but attach another format: ros2/rmw_zenoh ``rmw_zenoh_cpp/src/detail/
attachment_helpers.cpp`` at 0.2.3 serializes each field's name as a string before its
value (``"sequence_number"``, int64, ``"source_timestamp"``, int64, ``"source_gid"``,
the array), 77 bytes; 0.2.4 dropped the names (ros2/rmw_zenoh#605). Neither side reads
the other's samples: :meth:`Attachment.decode` raises :class:`OldAttachment`, which
names the versions.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Literal

import xxhash

ADMIN_SPACE = "@ros2_lv"
GID_SIZE = 16  # RMW_GID_STORAGE_SIZE in Jazzy
ATTACHMENT_SIZE = 8 + 8 + 1 + GID_SIZE

# RIHS01 type hashes of ROS 2 Jazzy's message definitions (REP-2016), as rosidl
# computes them and rmw_zenoh puts them into keys and tokens. tests/base checks each
# against rosbags' type store, which computes them from the definitions.
TYPE_HASHES: dict[str, str] = {
    "geometry_msgs/msg/Twist": (
        "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
    ),
    "geometry_msgs/msg/TwistStamped": (
        "RIHS01_5f0fcd4f81d5d06ad9b4c4c63e3ea51b82d6ae4d0558f1d475229b1121db6f64"
    ),
    "nav_msgs/msg/Odometry": (
        "RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0"
    ),
    "sensor_msgs/msg/LaserScan": (
        "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828"
    ),
    "sensor_msgs/msg/Imu": (
        "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b"
    ),
    "sensor_msgs/msg/BatteryState": (
        "RIHS01_4bee5dfce981c98faa6828b868307a0a73f992ed0789f374ee96c8f840e69741"
    ),
}

# the endpoints we declare: publishers and subscriptions; services (SS, SC) are not spoken
EntityKind = Literal["MP", "MS"]
# ROS 2 name rules (rcl) for configs: a node name is one token, a namespace absolute
NAME_PATTERN = r"^[A-Za-z_][A-Za-z0-9_]*$"
NAMESPACE_PATTERN = r"^/([A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*)?$"
TOPIC_PATTERN = r"^/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*$"  # relative or absolute


class WireError(ValueError):
    """A name, token or attachment that rmw_zenoh would not accept."""


class OldAttachment(WireError):
    """An attachment in the named-field format of rmw_zenoh_cpp before 0.2.4 (see the
    module doc): the peer runs a release whose samples we cannot read, nor it ours."""


def dds_type_name(ros_type: str) -> str:
    """``geometry_msgs/msg/Twist`` -> ``geometry_msgs::msg::dds_::Twist_``."""
    parts = ros_type.split("/")
    if len(parts) != 3 or not all(parts):
        raise WireError(f"ROS type {ros_type!r} is not package/msg/Name")
    pkg, kind, name = parts
    return f"{pkg}::{kind}::dds_::{name}_"


def fully_qualified(namespace: str, topic: str) -> str:
    """The absolute topic name of ``topic`` seen from a node in ``namespace``:
    ``("/husky", "odom")`` -> ``/husky/odom``; an absolute ``topic`` stays as it is.
    Private (``~``) names are not supported."""
    if not topic or topic.startswith("~") or "//" in topic or topic.endswith("/"):
        raise WireError(f"topic name {topic!r} is empty, private or malformed")
    if not namespace.startswith("/") or (namespace != "/" and namespace.endswith("/")):
        raise WireError(f"namespace {namespace!r} must be absolute, with no trailing '/'")
    if topic.startswith("/"):
        return topic
    return f"{namespace.rstrip('/')}/{topic}"


def mangle(name: str) -> str:
    """Zenoh keys cannot hold a ROS name's '/': rmw_zenoh writes '%' for each."""
    return name.replace("/", "%")


def topic_key(domain_id: int, fq_topic: str, ros_type: str, type_hash: str) -> str:
    """The data key of a topic: ``0/cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_..``."""
    return f"{domain_id}/{fq_topic.strip('/')}/{dds_type_name(ros_type)}/{type_hash}"


@dataclass(frozen=True)
class Qos:
    """The QoS an endpoint announces in its token (keep-last history, infinite
    deadline, lifespan and lease; automatic liveliness: what rclcpp uses by default).
    rmw_zenoh delivers whatever the QoS; it matters to graph tools and to a
    transient-local subscriber asking publishers' caches."""

    reliable: bool = True
    transient_local: bool = False
    depth: int = 10  # rclcpp's default for publishers and subscriptions


# rmw_qos_*_policy_e values (rmw/types.h)
_RELIABLE, _BEST_EFFORT = 1, 2
_TRANSIENT_LOCAL, _VOLATILE = 1, 2
# rmw_zenoh's defaults, which its QoS string leaves out (qos.cpp)
_DEFAULT_RELIABILITY, _DEFAULT_DURABILITY, _DEFAULT_DEPTH = _RELIABLE, _VOLATILE, 42

SENSOR_QOS = Qos(reliable=False, depth=5)  # rclcpp's SensorDataQoS


def qos_string(qos: Qos) -> str:
    """rmw_zenoh's ``qos_to_keyexpr``: ``<rel>:<dur>:<hist>,<depth>:<deadline s>,<ns>:
    <lifespan s>,<ns>:<liveliness>,<lease s>,<ns>`` with each default left empty. The
    default QoS(10) is ``::,10:,:,:,,``."""
    if qos.depth < 1:
        raise WireError(f"QoS depth {qos.depth} must be at least 1")
    rel = _RELIABLE if qos.reliable else _BEST_EFFORT
    dur = _TRANSIENT_LOCAL if qos.transient_local else _VOLATILE
    r = "" if rel == _DEFAULT_RELIABILITY else str(rel)
    d = "" if dur == _DEFAULT_DURABILITY else str(dur)
    n = "" if qos.depth == _DEFAULT_DEPTH else str(qos.depth)
    # keep-last history, infinite deadline/lifespan/lease, automatic liveliness: defaults
    return f"{r}:{d}:,{n}:,:,:,,"


def _token(
    domain_id: int,
    zid: str,
    node_id: int,
    entity_id: int,
    kind: str,
    enclave: str,
    namespace: str,
    node_name: str,
    *rest: str,
) -> str:
    """The fields every liveliness token starts with (the node's), then ``rest``."""
    _check_name(node_name)
    node = [mangle(enclave), mangle(namespace), mangle(node_name)]
    head = [ADMIN_SPACE, str(domain_id), zid, str(node_id), str(entity_id), kind]
    return "/".join([*head, *node, *rest])


def node_token(
    domain_id: int, zid: str, node_id: int, namespace: str, node_name: str, enclave: str = "/"
) -> str:
    """The liveliness token of a node: ``@ros2_lv/<domain>/<zid>/<nid>/<nid>/NN/
    <enclave>/<namespace>/<name>`` (names mangled; the root namespace is ``%``)."""
    return _token(domain_id, zid, node_id, node_id, "NN", enclave, namespace, node_name)


def endpoint_token(
    kind: EntityKind,
    domain_id: int,
    zid: str,
    node_id: int,
    entity_id: int,
    namespace: str,
    node_name: str,
    fq_topic: str,
    ros_type: str,
    type_hash: str,
    qos: Qos,
    enclave: str = "/",
) -> str:
    """The liveliness token of a publisher (``MP``) or subscription (``MS``): the
    node's fields, then ``<topic>/<type>/<hash>/<qos>`` (13 parts, none empty)."""
    return _token(
        domain_id,
        zid,
        node_id,
        entity_id,
        kind,
        enclave,
        namespace,
        node_name,
        mangle(fq_topic),
        dds_type_name(ros_type),
        type_hash,
        qos_string(qos),
    )


def _check_name(name: str) -> None:
    if not name or "/" in name:
        raise WireError(f"node name {name!r} is empty or holds '/'")


def gid_of(token: str) -> bytes:
    """An entity's 16-byte GID as rmw_zenoh computes it: XXH3-128 of its liveliness
    token, the low 64 bits then the high 64, each little-endian (see the module doc)."""
    # xxhash's 128-bit integer is high64 << 64 | low64: little-endian, it is those bytes
    return xxhash.xxh3_128_intdigest(token.encode()).to_bytes(GID_SIZE, "little")


# zenoh-ext writes a string as its LEB128 length, then its UTF-8 bytes
_OLD_PREFIX = bytes([len("sequence_number")]) + b"sequence_number"
OLD_ATTACHMENT_MESSAGE = (
    "attachment in rmw_zenoh_cpp's pre-0.2.4 named-field format: the ROS 2 peer runs "
    "rmw_zenoh_cpp 0.2.0-0.2.3 (Jazzy; or Rolling 0.3.0-0.5.0); phenorover speaks "
    "0.2.4 and later (Jazzy): upgrade ros-jazzy-rmw-zenoh-cpp"
)


@dataclass(frozen=True)
class Attachment:
    """What rmw_zenoh attaches to every sample: the publisher's sequence number (from
    1), the source timestamp (system clock, ns since the epoch) and its GID."""

    sequence_number: int
    source_timestamp_ns: int
    gid: bytes

    def encode(self) -> bytes:
        if len(self.gid) != GID_SIZE:
            raise WireError(f"GID has {len(self.gid)} bytes, not {GID_SIZE}")
        # zenoh-ext: int64 little-endian, int64, then the array as a sequence whose
        # LEB128 length (16) fits one byte
        return (
            struct.pack("<qqB", self.sequence_number, self.source_timestamp_ns, GID_SIZE) + self.gid
        )

    @classmethod
    def decode(cls, data: bytes) -> Attachment:
        """Raises OldAttachment for rmw_zenoh_cpp's pre-0.2.4 format, WireError naming
        what is wrong for anything else that is not 33 bytes of this format."""
        # as an int64 these bytes start a sequence number above 7e18, which one counted
        # from 1 never reaches: they are the old format's first field name
        if data.startswith(_OLD_PREFIX):
            raise OldAttachment(OLD_ATTACHMENT_MESSAGE)
        if len(data) != ATTACHMENT_SIZE:
            raise WireError(f"attachment has {len(data)} bytes, not {ATTACHMENT_SIZE}")
        seq, stamp, n = struct.unpack_from("<qqB", data)
        if n != GID_SIZE:
            raise WireError(f"attachment GID length is {n}, not {GID_SIZE}")
        return cls(seq, stamp, bytes(data[17:]))
