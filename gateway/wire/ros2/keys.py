"""rmw_zenoh's Zenoh key expressions: data keys, liveliness tokens, and entity GIDs.

From ``docs/design.md`` ("Topic and Service name mapping to Zenoh key expressions", "Graph
Cache") and ``rmw_zenoh_cpp/src/detail/liveliness_utils.cpp`` (``TopicInfo``, ``Entity``,
``mangle_name``) in the public repository ros2/rmw_zenoh (Jazzy and later):

* data key of a topic: ``<domain>/<fully qualified topic without its leading />/<DDS type
  name>/<type hash>``, e.g. ``0/robot1/cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_9c45...``.
  Humble's rmw_zenoh writes ``TypeHashNotSupported`` for the hash, so
  :func:`topic_subscription_key` puts ``*`` there;
* liveliness token of a node: ``@ros2_lv/<domain>/<zenoh id>/<node id>/<node id>/NN/<enclave>/
  <namespace>/<node name>``;
* of a publisher (``MP``), subscription (``MS``), service (``SS``) or client (``SC``): the same
  with the entity id and kind, then ``/<topic>/<DDS type name>/<type hash>/<qos>``;
* in tokens, names are "mangled": every ``/`` becomes ``%``, so the root namespace and the
  default enclave (``/``) are ``%`` and ``/robot1/cmd_vel`` is ``%robot1%cmd_vel``;
* the QoS chunk is :func:`gateway.wire.ros2.qos.qos_chunk`.

An entity's GID is not random: ``Entity::Entity`` hashes the whole liveliness key with
XXH3-128 and stores the low 64 bits then the high 64 bits, each in the host's byte order
(little endian on every platform ROS 2 ships for).  :func:`gid_of` does the same, so the GID in a
sample's attachment names the publisher token it belongs to.  Pure: no I/O.
"""

from __future__ import annotations

import enum
import re
import struct
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.core.errors import DecodeError, EncodeError
from gateway.wire.ros2.names import (
    validate_full_topic_name,
    validate_namespace,
    validate_node_name,
)
from gateway.wire.ros2.qos import QosProfile, parse_qos_chunk, qos_chunk
from gateway.wire.ros2.xxh3 import xxh3_128

if TYPE_CHECKING:
    from gateway.wire.ros2.types import RosType

#: First chunk of every rmw_zenoh liveliness token (a hermetic Zenoh namespace).
ADMIN_SPACE = "@ros2_lv"
#: What Humble's rmw_zenoh writes in place of the type hash.
HUMBLE_TYPE_HASH = "TypeHashNotSupported"
#: Chunks in the token of a node, and of any other entity.
NODE_TOKEN_CHUNKS = 9
ENTITY_TOKEN_CHUNKS = 13

_ZID = re.compile(r"[0-9a-f]{1,32}")
_DECIMAL = re.compile(r"[0-9]{1,20}")
_GID = struct.Struct("<QQ")


class EntityKind(str, enum.Enum):
    """The entity chunk of a liveliness token."""

    NODE = "NN"
    PUBLISHER = "MP"
    SUBSCRIPTION = "MS"
    SERVICE = "SS"
    CLIENT = "SC"


def mangle(name: str) -> str:
    """``name`` with every ``/`` replaced by ``%`` (rmw_zenoh's ``mangle_name``).

    >>> mangle("/robot1/cmd_vel")
    '%robot1%cmd_vel'
    """
    return name.replace("/", "%")


def demangle(chunk: str) -> str:
    """The inverse of :func:`mangle`."""
    return chunk.replace("%", "/")


def _domain(domain_id: int) -> str:
    if isinstance(domain_id, bool) or not isinstance(domain_id, int) or domain_id < 0:
        raise EncodeError(f"ROS domain id: expected an integer >= 0, got {domain_id!r}")
    return str(domain_id)


def _id(value: int, what: str) -> str:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise EncodeError(f"rmw_zenoh {what}: expected an integer >= 0, got {value!r}")
    return str(value)


def _zid(zid: str) -> str:
    if not isinstance(zid, str) or not _ZID.fullmatch(zid):
        raise EncodeError(f"Zenoh session id: expected 1 to 32 lowercase hex digits, "
                          f"got {zid!r}")
    return zid


def topic_key(domain_id: int, topic: str, ros_type: RosType) -> str:
    """The key expression of the data of ``topic`` (fully qualified) with type ``ros_type``.

    :raises ConfigError: an invalid topic name.
    :raises EncodeError: a negative or non-integer domain id.

    >>> from gateway.wire.ros2.types import TWIST
    >>> topic_key(0, "/robot1/cmd_vel", TWIST)[:50]
    '0/robot1/cmd_vel/geometry_msgs::msg::dds_::Twist_/'
    """
    full = validate_full_topic_name(topic)
    return f"{_domain(domain_id)}/{full[1:]}/{ros_type.dds_name}/{ros_type.type_hash}"


def topic_subscription_key(domain_id: int, topic: str, ros_type: RosType) -> str:
    """:func:`topic_key` with ``*`` for the hash: matches Jazzy's hash and Humble's
    ``TypeHashNotSupported`` alike."""
    full = validate_full_topic_name(topic)
    return f"{_domain(domain_id)}/{full[1:]}/{ros_type.dds_name}/*"


def node_token(domain_id: int, zid: str, node_id: int, namespace: str, node_name: str,
               enclave: str = "/") -> str:
    """The liveliness token key of a node.

    :param zid: the Zenoh session id as Zenoh prints it (lowercase hex).
    :param node_id: the node's id in its session (rmw_zenoh counts entities from 0).
    :param namespace: the node's namespace (``/`` for none).
    :param enclave: the SROS enclave (``/`` for none).
    :raises ConfigError: an invalid namespace, node name or enclave.
    :raises EncodeError: an invalid domain, session id or node id.

    >>> node_token(0, "aac3178e146ba6f1fc6e6a4085e77f21", 0, "/", "listener")
    '@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener'
    """
    nid = _id(node_id, "node id")
    return "/".join((
        ADMIN_SPACE, _domain(domain_id), _zid(zid), nid, nid, EntityKind.NODE.value,
        mangle(validate_namespace(enclave, "enclave")), mangle(validate_namespace(namespace)),
        validate_node_name(node_name),
    ))


def entity_token(kind: EntityKind, domain_id: int, zid: str, node_id: int, entity_id: int,
                 namespace: str, node_name: str, topic: str, ros_type: RosType,
                 qos: QosProfile, enclave: str = "/") -> str:
    """The liveliness token key of a publisher, subscription, service or client.

    :param kind: which kind of entity (not :attr:`EntityKind.NODE`).
    :param entity_id: the entity's id in its session, unique among the session's entities.
    :param topic: the fully qualified topic (or service) name.
    :param ros_type: the message type (its DDS name and hash go into the key).
    :param qos: the endpoint's QoS (see :func:`gateway.wire.ros2.qos.qos_chunk`).
    :raises ConfigError: an invalid name.
    :raises EncodeError: an invalid kind, domain, session id, id or QoS.
    """
    if not isinstance(kind, EntityKind) or kind is EntityKind.NODE:
        raise EncodeError(f"rmw_zenoh entity kind: expected MP, MS, SS or SC, got {kind!r}")
    return "/".join((
        ADMIN_SPACE, _domain(domain_id), _zid(zid), _id(node_id, "node id"),
        _id(entity_id, "entity id"), kind.value,
        mangle(validate_namespace(enclave, "enclave")), mangle(validate_namespace(namespace)),
        validate_node_name(node_name), mangle(validate_full_topic_name(topic)),
        ros_type.dds_name, ros_type.type_hash,
        qos_chunk(qos.reliability, qos.durability, qos.history, qos.depth),
    ))


@dataclass(frozen=True, slots=True)
class LivelinessToken:
    """One parsed liveliness token key.

    :param key: the key as received.
    :param domain_id: the ROS domain.
    :param zid: the Zenoh session id of the process.
    :param node_id: the node's id in that session.
    :param entity_id: the entity's id (the node id again for a node).
    :param kind: node, publisher, subscription, service or client.
    :param enclave: the SROS enclave, demangled (``/`` for none).
    :param namespace: the node's namespace, demangled (``/`` for none).
    :param node_name: the node's name.
    :param topic: fully qualified topic or service name; ``None`` for a node.
    :param type_name: DDS type name (``geometry_msgs::msg::dds_::Twist_``); ``None`` for a node.
    :param type_hash: RIHS01 hash (or Humble's placeholder); ``None`` for a node.
    :param qos: the endpoint's QoS; ``None`` for a node.
    """

    key: str
    domain_id: int
    zid: str
    node_id: int
    entity_id: int
    kind: EntityKind
    enclave: str
    namespace: str
    node_name: str
    topic: str | None = None
    type_name: str | None = None
    type_hash: str | None = None
    qos: QosProfile | None = None

    @property
    def gid(self) -> bytes:
        """The entity's GID, as its samples' attachments carry it (:func:`gid_of`)."""
        return gid_of(self.key)


def _decimal(chunk: str, what: str, key: str) -> int:
    if not _DECIMAL.fullmatch(chunk):
        raise DecodeError(f"rmw_zenoh liveliness token: expected a decimal {what}, "
                          f"got {chunk!r} in {key!r}")
    return int(chunk)


def parse_token(key: str) -> LivelinessToken:
    """The parts of a liveliness token key (see the module docstring for the layout).

    :raises DecodeError: not a key of ``@ros2_lv``, the wrong number of chunks for its kind,
        an empty chunk, a non-decimal domain or id, a session id that is not hex, an unknown
        kind, or a malformed QoS chunk.
    """
    entity = "rmw_zenoh liveliness token"
    if not isinstance(key, str):
        raise DecodeError(f"{entity}: expected a str, got {type(key).__name__}")
    chunks = key.split("/")
    if chunks[0] != ADMIN_SPACE:
        raise DecodeError(f"{entity}: expected a key starting with {ADMIN_SPACE}/, got {key!r}")
    if len(chunks) not in (NODE_TOKEN_CHUNKS, ENTITY_TOKEN_CHUNKS):
        raise DecodeError(f"{entity}: expected {NODE_TOKEN_CHUNKS} or {ENTITY_TOKEN_CHUNKS} "
                          f"chunks, got {len(chunks)} in {key!r}")
    if "" in chunks:
        raise DecodeError(f"{entity}: expected no empty chunk, got one in {key!r}")
    try:
        kind = EntityKind(chunks[5])
    except ValueError:
        raise DecodeError(f"{entity}: expected an entity kind of NN, MP, MS, SS or SC, "
                          f"got {chunks[5]!r} in {key!r}") from None
    expected = NODE_TOKEN_CHUNKS if kind is EntityKind.NODE else ENTITY_TOKEN_CHUNKS
    if len(chunks) != expected:
        raise DecodeError(f"{entity}: expected {expected} chunks for kind {kind.value}, "
                          f"got {len(chunks)} in {key!r}")
    if not _ZID.fullmatch(chunks[2]):
        raise DecodeError(f"{entity}: expected a Zenoh id of 1 to 32 lowercase hex digits, "
                          f"got {chunks[2]!r} in {key!r}")
    node = kind is EntityKind.NODE
    return LivelinessToken(
        key=key,
        domain_id=_decimal(chunks[1], "domain id", key),
        zid=chunks[2],
        node_id=_decimal(chunks[3], "node id", key),
        entity_id=_decimal(chunks[4], "entity id", key),
        kind=kind,
        enclave=demangle(chunks[6]),
        namespace=demangle(chunks[7]),
        node_name=demangle(chunks[8]),
        topic=None if node else demangle(chunks[9]),
        type_name=None if node else demangle(chunks[10]),
        type_hash=None if node else demangle(chunks[11]),
        qos=None if node else parse_qos_chunk(chunks[12]),
    )


def gid_of(token_key: str) -> bytes:
    """The 16-byte GID rmw_zenoh gives the entity whose liveliness token key is ``token_key``.

    XXH3-128 of the key's bytes, low half then high half, little endian
    (``Entity::Entity`` in ``rmw_zenoh_cpp/src/detail/liveliness_utils.cpp``).  Any string
    hashes; it is the entity's GID only if it is the token key exactly as declared.

    >>> gid_of("@ros2_lv/0/1/0/0/NN/%/%/n").hex()
    'b4d15b855bf91fc3aa0bf846b348653d'
    """
    low, high = xxh3_128(token_key.encode("utf-8"))
    return _GID.pack(low, high)
