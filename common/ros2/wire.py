"""ROS 2 over Zenoh as rmw_zenoh speaks it: key expressions, liveliness tokens, QoS
strings, the per-message attachment and the type names and hashes. Pure: no I/O.

Pinned: **rmw_zenoh_cpp 0.2.10**, the ROS 2 Jazzy release (Zenoh 1.x). Read from the
source bloom released, github.com/ros2-gbp/rmw_zenoh-release at tag
``release/jazzy/rmw_zenoh_cpp/0.2.10-1`` (ros2/rmw_zenoh's ``jazzy`` branch):

- ``src/detail/liveliness_utils.cpp``: the token layout (``KeyexprIndex``), the QoS
  string (``qos_to_keyexpr``), ``mangle_name`` ('/' -> '%') and the data key
  (``TopicInfo``: ``<domain>/<topic without outer slashes>/<type>/<hash>``);
- ``src/detail/attachment_helpers.cpp``: ``AttachmentData::serialize_to_zbytes``, a
  zenoh-ext Serializer fed int64 sequence number, int64 source timestamp and the
  ``std::array<uint8_t, 16>`` GID; zenoh-cpp's ``include/zenoh/api/ext/
  serialization.hxx`` writes a std::array as a sequence (LEB128 length, then the
  bytes), so the attachment is 33 bytes: ``<q <q 0x10 gid[16]``;
- ``src/detail/rmw_publisher_data.cpp``: sequence numbers start at 1, the source
  timestamp is the system clock in ns, node and entity ids come from one counter per
  context (session);
- ``src/detail/qos.cpp``: the defaults a QoS string leaves empty (reliable, volatile,
  keep-last 42, infinite durations);
- ``src/detail/type_support_common.cpp``: type names ``pkg::msg::dds_::Type_``.

The design document (ros2/rmw_zenoh ``docs/design.md``) describes the same layout.
Earlier releases (0.0.x, Zenoh 0.11) spoke another format: named attachment fields and
shorter tokens; a peer on those does not interoperate with this module.

One deliberate difference: rmw_zenoh derives an entity's GID from the XXH3-128 hash
of its liveliness token; we use BLAKE2b-128 of the same token (no xxhash in the
standard library). The GID is opaque to subscribers (it is reported as the publisher
GID of each message), so only ``ros2 topic info -v``'s GIDs would differ.
"""

from __future__ import annotations

import hashlib
import struct
from dataclasses import dataclass
from typing import Literal

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
}

EntityKind = Literal["NN", "MP", "MS", "SS", "SC"]
# ROS 2 name rules (rcl) for configs: a node name is one token, a namespace absolute
NAME_PATTERN = r"^[A-Za-z_][A-Za-z0-9_]*$"
NAMESPACE_PATTERN = r"^/([A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*)?$"
TOPIC_PATTERN = r"^/?[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*$"  # relative or absolute


class WireError(ValueError):
    """A name, token or attachment that rmw_zenoh would not accept."""


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
    """An entity's 16-byte GID, a hash of its liveliness token (see the module doc)."""
    return hashlib.blake2b(token.encode(), digest_size=GID_SIZE).digest()


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
        """Raises WireError naming what is wrong."""
        if len(data) != ATTACHMENT_SIZE:
            raise WireError(f"attachment has {len(data)} bytes, not {ATTACHMENT_SIZE}")
        seq, stamp, n = struct.unpack_from("<qqB", data)
        if n != GID_SIZE:
            raise WireError(f"attachment GID length is {n}, not {GID_SIZE}")
        return cls(seq, stamp, bytes(data[17:]))
