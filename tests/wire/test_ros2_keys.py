"""rmw_zenoh's key expressions: data keys, liveliness tokens, their QoS chunk, entity GIDs.

The expected keys are the examples of rmw_zenoh's ``docs/design.md`` (ros2/rmw_zenoh), rebuilt
from their parts; the GIDs were computed with the reference xxHash C library.
"""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from gateway.core.errors import ConfigError, DecodeError, EncodeError
from gateway.wire.ros2 import (
    TWIST,
    Durability,
    EntityKind,
    History,
    LivelinessToken,
    QosProfile,
    Reliability,
    RosType,
    entity_token,
    gid_of,
    node_token,
    parse_qos_chunk,
    parse_token,
    qos_chunk,
    topic_key,
    topic_subscription_key,
)

STRING = RosType("std_msgs/msg/String",
                 "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18")
LISTENER_ZID = "aac3178e146ba6f1fc6e6a4085e77f21"
TALKER_ZID = "8b20917502ee955ac4476e0266340d5c"
LISTENER_NODE = f"@ros2_lv/2/{LISTENER_ZID}/0/0/NN/%/%/listener"
LISTENER_SUB = (f"@ros2_lv/2/{LISTENER_ZID}/0/10/MS/%/%/listener/%chatter/"
                f"std_msgs::msg::dds_::String_/{STRING.type_hash}/::,10:,:,:,,")
TALKER_PUB = (f"@ros2_lv/2/{TALKER_ZID}/0/10/MP/%/%/talker/%chatter/"
              f"std_msgs::msg::dds_::String_/{STRING.type_hash}/::,7:,:,:,,")


# ----------------------------------------------------------------------------- data keys


def test_data_keys_of_the_design_document() -> None:
    assert topic_key(0, "/chatter", STRING) == (
        f"0/chatter/std_msgs::msg::dds_::String_/{STRING.type_hash}")
    assert topic_key(0, "/robot1/chatter", STRING) == (
        f"0/robot1/chatter/std_msgs::msg::dds_::String_/{STRING.type_hash}")


def test_data_keys_of_cmd_vel() -> None:
    assert topic_key(3, "/robot1/cmd_vel", TWIST) == (
        "3/robot1/cmd_vel/geometry_msgs::msg::dds_::Twist_/"
        "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a")
    assert topic_subscription_key(0, "/cmd_vel", TWIST) == (
        "0/cmd_vel/geometry_msgs::msg::dds_::Twist_/*")


@pytest.mark.parametrize(("domain", "topic", "error"), [
    (-1, "/cmd_vel", EncodeError),
    (True, "/cmd_vel", EncodeError),
    ("0", "/cmd_vel", EncodeError),
    (0, "cmd_vel", ConfigError),
    (0, "/cmd_vel/", ConfigError),
])
def test_bad_data_key_parts_are_refused(domain: object, topic: str,
                                        error: type[Exception]) -> None:
    with pytest.raises(error):
        topic_key(domain, topic, TWIST)  # type: ignore[arg-type]
    with pytest.raises(error):
        topic_subscription_key(domain, topic, TWIST)  # type: ignore[arg-type]


# ----------------------------------------------------------------------------- QoS chunk


@pytest.mark.parametrize(("reliability", "durability", "history", "depth", "chunk"), [
    (Reliability.RELIABLE, Durability.VOLATILE, History.KEEP_LAST, 10, "::,10:,:,:,,"),
    (Reliability.RELIABLE, Durability.VOLATILE, History.KEEP_LAST, 42, "::,:,:,:,,"),
    (Reliability.RELIABLE, Durability.VOLATILE, History.KEEP_LAST, 0, "::,:,:,:,,"),
    (Reliability.BEST_EFFORT, Durability.VOLATILE, History.KEEP_LAST, 5, "2::,5:,:,:,,"),
    (Reliability.RELIABLE, Durability.TRANSIENT_LOCAL, History.KEEP_LAST, 1, ":1:,1:,:,:,,"),
    (Reliability.RELIABLE, Durability.VOLATILE, History.KEEP_ALL, 10, "::2,10:,:,:,,"),
    (Reliability.SYSTEM_DEFAULT, Durability.SYSTEM_DEFAULT, History.SYSTEM_DEFAULT, 0,
     "::,:,:,:,,"),
])
def test_the_qos_chunk_leaves_rmw_zenohs_defaults_empty(
        reliability: Reliability, durability: Durability, history: History, depth: int,
        chunk: str) -> None:
    assert qos_chunk(reliability, durability, history, depth) == chunk


@pytest.mark.parametrize(("chunk", "profile"), [
    ("::,10:,:,:,,", QosProfile(depth=10)),
    ("::,:,:,:,,", QosProfile(depth=42)),
    ("2:1:,1:,:,:,,", QosProfile(Reliability.BEST_EFFORT, Durability.TRANSIENT_LOCAL,
                                 History.KEEP_LAST, 1)),
    ("1:2:1,10:,:,:,,", QosProfile(depth=10)),
    ("0:0:0,0:,:,:,,", QosProfile(depth=42)),
    ("1:2:2,1000:9223372036,854775807:9223372036,854775807:1,9223372036,854775807",
     QosProfile(history=History.KEEP_ALL, depth=1000)),
])
def test_qos_chunks_parse_in_the_current_and_the_older_form(chunk: str,
                                                            profile: QosProfile) -> None:
    assert parse_qos_chunk(chunk) == profile


@pytest.mark.parametrize(("chunk", "error"), [
    ("::,10:,:,", r"expected 6 parts separated by ':', got 5"),
    ("::,10:,:,:,,:", r"expected 6 parts separated by ':', got 7"),
    (":::,:,:,,", r"expected history,depth:deadline s,ns"),
    ("::,10:,:,:,", r"expected history,depth"),
    ("x::,10:,:,:,,", r"expected a decimal number for reliability, got 'x'"),
    ("9::,10:,:,:,,", r"expected a reliability of 0 \(SYSTEM_DEFAULT\), 1 \(RELIABLE\), "
                      r"2 \(BEST_EFFORT\), got 9"),
    (":3:,10:,:,:,,", r"expected a durability of"),
    ("::,-1:,:,:,,", r"expected a decimal number for depth, got '-1'"),
    ("::,10:1.5,:,:,,", r"expected a decimal number for a duration or the liveliness"),
])
def test_malformed_qos_chunks_are_decode_errors(chunk: str, error: str) -> None:
    with pytest.raises(DecodeError, match=f"^rmw_zenoh QoS chunk: {error}"):
        parse_qos_chunk(chunk)


def test_the_qos_chunk_refuses_values_it_cannot_write() -> None:
    with pytest.raises(EncodeError, match=r"expected a Reliability, got 1"):
        qos_chunk(1)  # type: ignore[arg-type]
    with pytest.raises(EncodeError, match=r"expected a depth from 0 to 4294967295, got -1"):
        qos_chunk(depth=-1)


# ----------------------------------------------------------------------------- tokens


def test_tokens_of_the_design_document_are_rebuilt() -> None:
    assert node_token(2, LISTENER_ZID, 0, "/", "listener") == LISTENER_NODE
    assert entity_token(EntityKind.SUBSCRIPTION, 2, LISTENER_ZID, 0, 10, "/", "listener",
                        "/chatter", STRING, QosProfile(depth=10)) == LISTENER_SUB
    assert entity_token(EntityKind.PUBLISHER, 2, TALKER_ZID, 0, 10, "", "talker", "/chatter",
                        STRING, QosProfile(depth=7)) == TALKER_PUB


def test_namespaces_and_topics_are_mangled() -> None:
    token = entity_token(EntityKind.PUBLISHER, 0, "1f", 3, 4, "robot1", "wheelgate",
                         "/robot1/odom", TWIST, QosProfile(), enclave="/secure")
    assert token == ("@ros2_lv/0/1f/3/4/MP/%secure/%robot1/wheelgate/%robot1%odom/"
                     f"geometry_msgs::msg::dds_::Twist_/{TWIST.type_hash}/::,10:,:,:,,")


@pytest.mark.parametrize(("kwargs", "error", "message"), [
    ({"kind": EntityKind.NODE}, EncodeError, r"expected MP, MS, SS or SC, got"),
    ({"zid": "AAC3"}, EncodeError, r"expected 1 to 32 lowercase hex digits, got 'AAC3'"),
    ({"zid": "0" * 33}, EncodeError, r"lowercase hex digits"),
    ({"entity_id": -1}, EncodeError, r"entity id: expected an integer >= 0, got -1"),
    ({"node_id": "0"}, EncodeError, r"node id: expected an integer >= 0, got '0'"),
    ({"namespace": "/robot 1"}, ConfigError, r"^namespace: expected"),
    ({"node_name": "a/b"}, ConfigError, r"^node name: expected"),
    ({"topic": "odom"}, ConfigError, r"^topic name: expected a fully qualified name"),
    ({"enclave": "//"}, ConfigError, r"^enclave: expected"),
])
def test_bad_token_parts_are_refused(kwargs: dict[str, object], error: type[Exception],
                                     message: str) -> None:
    parts: dict[str, object] = {
        "kind": EntityKind.PUBLISHER, "domain_id": 0, "zid": "1f", "node_id": 0,
        "entity_id": 1, "namespace": "/", "node_name": "n", "topic": "/odom",
        "ros_type": TWIST, "qos": QosProfile(), **kwargs}
    with pytest.raises(error, match=message):
        entity_token(**parts)  # type: ignore[arg-type]


def test_tokens_parse_into_their_parts() -> None:
    assert parse_token(LISTENER_NODE) == LivelinessToken(
        LISTENER_NODE, 2, LISTENER_ZID, 0, 0, EntityKind.NODE, "/", "/", "listener")
    assert parse_token(TALKER_PUB) == LivelinessToken(
        TALKER_PUB, 2, TALKER_ZID, 0, 10, EntityKind.PUBLISHER, "/", "/", "talker",
        "/chatter", "std_msgs::msg::dds_::String_", STRING.type_hash, QosProfile(depth=7))
    namespaced = parse_token(entity_token(
        EntityKind.SUBSCRIPTION, 0, "1f", 3, 4, "/robot1", "wheelgate", "/robot1/cmd_vel",
        TWIST, QosProfile(Reliability.BEST_EFFORT, depth=1)))
    assert (namespaced.namespace, namespaced.topic, namespaced.qos) == (
        "/robot1", "/robot1/cmd_vel", QosProfile(Reliability.BEST_EFFORT, depth=1))


def test_a_humble_style_hash_is_kept_as_it_came() -> None:
    token = TALKER_PUB.replace(STRING.type_hash, "TypeHashNotSupported")
    assert parse_token(token).type_hash == "TypeHashNotSupported"


@pytest.mark.parametrize(("key", "error"), [
    ("@ros2_lx/2/1f/0/0/NN/%/%/listener", r"expected a key starting with @ros2_lv/"),
    ("@ros2_lv/2/1f/0/0/NN/%/%", r"expected 9 or 13 chunks, got 8"),
    ("@ros2_lv/2/1f/0/0/NN/%/%/listener/x", r"expected 9 or 13 chunks, got 10"),
    ("@ros2_lv/2/1f/0/0/XX/%/%/listener", r"expected an entity kind of NN, MP, MS, SS or SC, "
                                          r"got 'XX'"),
    ("@ros2_lv/2/1f/0/0/NN//%/listener", r"expected no empty chunk"),
    ("@ros2_lv/-2/1f/0/0/NN/%/%/listener", r"expected a decimal domain id, got '-2'"),
    ("@ros2_lv/2/1F/0/0/NN/%/%/listener", r"expected a Zenoh id of 1 to 32 lowercase hex"),
    ("@ros2_lv/2/1f/a/0/NN/%/%/listener", r"expected a decimal node id, got 'a'"),
    ("@ros2_lv/2/1f/0/٣/NN/%/%/listener", r"expected a decimal entity id, got '٣'"),
    (LISTENER_NODE.replace("/NN/", "/MS/"), r"expected 13 chunks for kind MS, got 9"),
    (TALKER_PUB.replace("/MP/", "/NN/"), r"expected 9 chunks for kind NN, got 13"),
])
def test_malformed_tokens_are_decode_errors(key: str, error: str) -> None:
    with pytest.raises(DecodeError, match=f"^rmw_zenoh liveliness token: {error}"):
        parse_token(key)


def test_a_bad_qos_chunk_in_a_token_is_a_decode_error() -> None:
    with pytest.raises(DecodeError, match=r"^rmw_zenoh QoS chunk: expected 6 parts"):
        parse_token(TALKER_PUB.replace("::,7:,:,:,,", "::,7"))


NAMES = st.from_regex(r"[a-z_][a-z0-9_]{0,8}", fullmatch=True)


@given(st.sampled_from([k for k in EntityKind if k is not EntityKind.NODE]),
       st.integers(0, 232), st.from_regex(r"[0-9a-f]{1,32}", fullmatch=True),
       st.integers(0, 2**32), st.integers(0, 2**32), st.lists(NAMES, max_size=3), NAMES,
       st.lists(NAMES, min_size=1, max_size=3), st.sampled_from(Reliability),
       st.sampled_from(Durability), st.sampled_from(History), st.integers(1, 1000))
def test_built_tokens_parse_back(kind: EntityKind, domain: int, zid: str, nid: int, eid: int,
                                 ns: list[str], node: str, topic: list[str],
                                 reliability: Reliability, durability: Durability,
                                 history: History, depth: int) -> None:
    namespace = "/" + "/".join(ns)
    full_topic = "/" + "/".join(topic)
    qos = QosProfile(reliability, durability, history, depth)
    key = entity_token(kind, domain, zid, nid, eid, namespace, node, full_topic, TWIST, qos)
    token = parse_token(key)
    assert (token.kind, token.domain_id, token.zid, token.node_id, token.entity_id) == (
        kind, domain, zid, nid, eid)
    assert (token.namespace, token.node_name, token.topic) == (namespace, node, full_topic)
    assert (token.type_name, token.type_hash) == (TWIST.dds_name, TWIST.type_hash)
    assert token.qos is not None and parse_qos_chunk(qos_chunk(
        token.qos.reliability, token.qos.durability, token.qos.history, token.qos.depth)) \
        == token.qos


@given(st.one_of(st.text(max_size=80),
                 st.lists(st.text("%:,019aNMPS/", max_size=6), max_size=14).map(
                     lambda chunks: "/".join(["@ros2_lv", *chunks]))))
def test_arbitrary_keys_raise_only_decode_errors(key: str) -> None:
    try:
        parse_token(key)
    except DecodeError:
        pass


# ----------------------------------------------------------------------------- GIDs


@pytest.mark.parametrize(("key", "gid"), [
    (LISTENER_NODE, "49877999dacb858702d11ac823785912"),
    (LISTENER_SUB, "76148a538308fe55a6c5375462ca1de6"),
    (TALKER_PUB, "ac170f31eadcd9ff0cd86d7a17907d1c"),
])
def test_the_gid_is_the_xxh3_128_of_the_token_key(key: str, gid: str) -> None:
    assert gid_of(key).hex() == gid
    assert parse_token(key).gid.hex() == gid


def test_every_part_of_a_token_changes_the_gid() -> None:
    gids = {gid_of(TALKER_PUB.replace("/10/MP/", f"/{n}/MP/")) for n in range(50)}
    assert len(gids) == 50
    assert all(len(g) == 16 for g in gids)
