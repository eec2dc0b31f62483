"""The pure-Python XXH3-128 that rmw_zenoh's entity GIDs need, against the reference.

Literal digests (taken once from the reference C library, xxHash 0.8) cover every branch of the
algorithm: 0, 1-3, 4-8, 9-16, 17-128, 129-240 bytes and the long loop with one, two and three
blocks.  Where the system has ``libxxhash`` (Debian: ``libxxhash0``) the implementation is also
compared with it on many lengths; that test is skipped elsewhere.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import random
import struct

import pytest

from gateway.wire.ros2.xxh3 import xxh3_128

#: length -> XXH3-128 of ``bytes((i * 7 + 3) % 256 for i in range(length))``, as low64 then
#: high64, little endian (the byte order of an rmw_zenoh GID).
DIGESTS = {
    0: "7f498d4624c30160d8984701d306aa99",
    1: "edef6d15bc08e613ba391a216bb7bb22",
    2: "6cb84339b974901c228744b153ddb9a6",
    3: "1c485b48da8d08a9a54582bf3c7631ce",
    4: "20feb05491608a78b146075970791947",
    8: "88153ad6e324d03c551517465f8abce3",
    9: "9f1023f1c7b1faead7569a7a24882cc7",
    16: "240ad4475e5cd76084f824ab47960bce",
    17: "d7262a315476edee12bd2fcced27d3bf",
    64: "67d29cc6729d54aa632b8b6afe53d9fe",
    96: "bb7a90bccf3bb60a7ab36d989504352a",
    128: "53ac926c8b0080c58bc7ba96a062191b",
    129: "5b384dce7ace91bd239061c468493e29",
    160: "d08f0a86028e290eb65ab77ca31915d7",
    191: "eb0b74235cec9627f253f70892978b73",
    192: "ac1f524c7698d94ec67fee4b7837005b",
    240: "0be8be34f0b5e004c76b071b02c146ad",
    241: "17fe74883addea8b5db4d6c392346cac",
    1024: "b1721c641c66819b3636a3a9ac0ebc18",
    1025: "763571ed72206c807c8da9cf517244bf",
    2048: "d12ea63b8104e6ab75808d418f6e1ff8",
    3000: "3d6b3c87bb7891c84f6a4622a042882f",
}


def digest(data: bytes) -> str:
    return struct.pack("<QQ", *xxh3_128(data)).hex()


@pytest.mark.parametrize("length", sorted(DIGESTS))
def test_known_digests(length: int) -> None:
    assert digest(bytes((i * 7 + 3) % 256 for i in range(length))) == DIGESTS[length]


class _Hash128(ctypes.Structure):
    _fields_ = (("low64", ctypes.c_uint64), ("high64", ctypes.c_uint64))


def test_matches_the_system_libxxhash_on_every_short_length_and_some_long_ones() -> None:
    name = ctypes.util.find_library("xxhash") or "libxxhash.so.0"
    try:
        lib = ctypes.CDLL(name)
    except OSError:
        pytest.skip("libxxhash is not installed (Debian: apt-get install libxxhash0)")
    reference = lib.XXH3_128bits
    reference.restype = _Hash128
    reference.argtypes = (ctypes.c_char_p, ctypes.c_size_t)
    rng = random.Random(2011)
    for length in [*range(300), 1023, 1024, 1025, 1088, 2049, 4097]:
        data = rng.randbytes(length)
        expected = reference(data, length)
        assert xxh3_128(data) == (expected.low64, expected.high64), f"length {length}"
