"""XXH3-128 (seed 0, default secret) in pure Python: how rmw_zenoh derives an entity's GID.

rmw_zenoh hashes the liveliness key of every entity with XXH3-128 and uses the digest as the
entity's 16-byte GID (``rmw_zenoh_cpp/src/detail/liveliness_utils.cpp``, ``Entity::Entity``, in
the public repository ros2/rmw_zenoh); the hash itself is a portable copy of xxHash 0.8
(``rmw_zenoh_cpp/src/detail/simplified_xxhash3.cpp``, from the public repository
Cyan4973/xxHash).  This module follows that copy branch by branch, so the digests equal the
reference ``XXH3_128bits`` for every length.  Pure: no I/O.

It is slow next to the C library (some microseconds for a liveliness key), which is fine for the
handful of keys a bridge sees.
"""

from __future__ import annotations

import struct

_M64 = (1 << 64) - 1
_M32 = (1 << 32) - 1

_P32_1 = 0x9E3779B1
_P32_2 = 0x85EBCA77
_P32_3 = 0xC2B2AE3D
_P64_1 = 0x9E3779B185EBCA87
_P64_2 = 0xC2B2AE3D27D4EB4F
_P64_3 = 0x165667B19E3779F9
_P64_4 = 0x85EBCA77C2B2AE63
_P64_5 = 0x27D4EB2F165667C5
_PRIME_MX1 = 0x165667919E3779F9
_PRIME_MX2 = 0x9FB21C651E98DF25

_SECRET = bytes.fromhex(
    "b8fe6c3923a44bbe7c01812cf721ad1cded46de9839097db7240a4a4b7b3671f"
    "cb79e64eccc0e578825ad07dccff7221b8084674f743248ee03590e6813a264c"
    "3c2852bb91c300cb88d0658b1b532ea371644897a20df94e3819ef46a9deacd8"
    "a8fa763fe39c343ff9dcbbc7c70b4f1d8a51e04bcdb45931c89f7ec9d9787364"
    "eac5ac8334d3ebc3c581a0fffa1363eb170ddd51b7f0da49d316552629d4689e"
    "2b16be587d47a1fc8ff8b8d17ad031ce45cb3a8f95160428afd7fbcabb4b407e"
)
_STRIPE_LEN = 64
_SECRET_CONSUME_RATE = 8
_MIDSIZE_MAX = 240
_MIDSIZE_STARTOFFSET = 3
_MIDSIZE_LASTOFFSET = 17
_SECRET_SIZE_MIN = 136
_SECRET_LASTACC_START = 7
_SECRET_MERGEACCS_START = 11

_U64 = struct.Struct("<Q")
_U32 = struct.Struct("<I")
_STRIPE = struct.Struct("<8Q")


def _r64(data: bytes, offset: int) -> int:
    return int(_U64.unpack_from(data, offset)[0])


def _r32(data: bytes, offset: int) -> int:
    return int(_U32.unpack_from(data, offset)[0])


def _mul128(lhs: int, rhs: int) -> tuple[int, int]:
    """(low, high) 64-bit halves of the 128-bit product."""
    product = lhs * rhs
    return product & _M64, product >> 64


def _fold64(lhs: int, rhs: int) -> int:
    low, high = _mul128(lhs, rhs)
    return low ^ high


def _avalanche(h: int) -> int:
    h ^= h >> 37
    h = (h * _PRIME_MX1) & _M64
    return h ^ (h >> 32)


def _avalanche64(h: int) -> int:
    h ^= h >> 33
    h = (h * _P64_2) & _M64
    h ^= h >> 29
    h = (h * _P64_3) & _M64
    return h ^ (h >> 32)


def _swap64(x: int) -> int:
    return int.from_bytes(x.to_bytes(8, "little"), "big")


def _swap32(x: int) -> int:
    return int.from_bytes(x.to_bytes(4, "little"), "big")


def _len_1to3(data: bytes) -> tuple[int, int]:
    n = len(data)
    combined_l = (data[0] << 16) | (data[n >> 1] << 24) | data[n - 1] | (n << 8)
    swapped = _swap32(combined_l)
    combined_h = ((swapped << 13) | (swapped >> 19)) & _M32
    flip_l = _r32(_SECRET, 0) ^ _r32(_SECRET, 4)
    flip_h = _r32(_SECRET, 8) ^ _r32(_SECRET, 12)
    return _avalanche64(combined_l ^ flip_l), _avalanche64(combined_h ^ flip_h)


def _len_4to8(data: bytes) -> tuple[int, int]:
    n = len(data)
    value = _r32(data, 0) + (_r32(data, n - 4) << 32)
    keyed = value ^ (_r64(_SECRET, 16) ^ _r64(_SECRET, 24))
    low, high = _mul128(keyed, (_P64_1 + (n << 2)) & _M64)
    high = (high + (low << 1)) & _M64
    low ^= high >> 3
    low ^= low >> 35
    low = (low * _PRIME_MX2) & _M64
    low ^= low >> 28
    return low, _avalanche(high)


def _len_9to16(data: bytes) -> tuple[int, int]:
    n = len(data)
    flip_l = _r64(_SECRET, 32) ^ _r64(_SECRET, 40)
    flip_h = _r64(_SECRET, 48) ^ _r64(_SECRET, 56)
    input_lo = _r64(data, 0)
    input_hi = _r64(data, n - 8)
    low, high = _mul128(input_lo ^ input_hi ^ flip_l, _P64_1)
    low = (low + ((n - 1) << 54)) & _M64
    input_hi ^= flip_h
    high = (high + input_hi + (input_hi & _M32) * (_P32_2 - 1)) & _M64
    low ^= _swap64(high)
    h_low, h_high = _mul128(low, _P64_2)
    h_high = (h_high + high * _P64_2) & _M64
    return _avalanche(h_low), _avalanche(h_high)


def _mix16(data: bytes, offset: int, secret_offset: int) -> int:
    return _fold64(
        _r64(data, offset) ^ _r64(_SECRET, secret_offset),
        _r64(data, offset + 8) ^ _r64(_SECRET, secret_offset + 8),
    )


def _mix32(acc: tuple[int, int], data: bytes, in1: int, in2: int, secret_offset: int
           ) -> tuple[int, int]:
    low, high = acc
    low = (low + _mix16(data, in1, secret_offset)) & _M64
    low ^= (_r64(data, in2) + _r64(data, in2 + 8)) & _M64
    high = (high + _mix16(data, in2, secret_offset + 16)) & _M64
    high ^= (_r64(data, in1) + _r64(data, in1 + 8)) & _M64
    return low, high


def _finish_mid(acc: tuple[int, int], n: int) -> tuple[int, int]:
    low, high = acc
    h_low = (low + high) & _M64
    h_high = (low * _P64_1 + high * _P64_4 + n * _P64_2) & _M64
    return _avalanche(h_low), (-_avalanche(h_high)) & _M64


def _len_17to128(data: bytes) -> tuple[int, int]:
    n = len(data)
    acc = ((n * _P64_1) & _M64, 0)
    if n > 32:
        if n > 64:
            if n > 96:
                acc = _mix32(acc, data, 48, n - 64, 96)
            acc = _mix32(acc, data, 32, n - 48, 64)
        acc = _mix32(acc, data, 16, n - 32, 32)
    acc = _mix32(acc, data, 0, n - 16, 0)
    return _finish_mid(acc, n)


def _len_129to240(data: bytes) -> tuple[int, int]:
    n = len(data)
    acc = ((n * _P64_1) & _M64, 0)
    for i in range(32, 160, 32):
        acc = _mix32(acc, data, i - 32, i - 16, i - 32)
    acc = (_avalanche(acc[0]), _avalanche(acc[1]))
    for i in range(160, n + 1, 32):
        acc = _mix32(acc, data, i - 32, i - 16, _MIDSIZE_STARTOFFSET + i - 160)
    acc = _mix32(acc, data, n - 16, n - 32, _SECRET_SIZE_MIN - _MIDSIZE_LASTOFFSET - 16)
    return _finish_mid(acc, n)


def _accumulate_512(acc: list[int], data: bytes, offset: int, secret_offset: int) -> None:
    values = _STRIPE.unpack_from(data, offset)
    keys = _STRIPE.unpack_from(_SECRET, secret_offset)
    for lane in range(8):
        value = values[lane]
        keyed = value ^ keys[lane]
        acc[lane ^ 1] = (acc[lane ^ 1] + value) & _M64
        acc[lane] = (acc[lane] + (keyed & _M32) * (keyed >> 32)) & _M64


def _scramble(acc: list[int]) -> None:
    keys = _STRIPE.unpack_from(_SECRET, len(_SECRET) - _STRIPE_LEN)
    for lane in range(8):
        value = acc[lane]
        value ^= value >> 47
        value ^= keys[lane]
        acc[lane] = (value * _P32_1) & _M64


def _merge(acc: list[int], secret_offset: int, start: int) -> int:
    result = start
    for i in range(4):
        result += _fold64(
            acc[2 * i] ^ _r64(_SECRET, secret_offset + 16 * i),
            acc[2 * i + 1] ^ _r64(_SECRET, secret_offset + 16 * i + 8),
        )
    return _avalanche(result & _M64)


def _long(data: bytes) -> tuple[int, int]:
    n = len(data)
    acc = [_P32_3, _P64_1, _P64_2, _P64_3, _P64_4, _P32_2, _P64_5, _P32_1]
    stripes_per_block = (len(_SECRET) - _STRIPE_LEN) // _SECRET_CONSUME_RATE
    block_len = _STRIPE_LEN * stripes_per_block
    blocks = (n - 1) // block_len
    for block in range(blocks):
        for stripe in range(stripes_per_block):
            _accumulate_512(acc, data, block * block_len + stripe * _STRIPE_LEN,
                            stripe * _SECRET_CONSUME_RATE)
        _scramble(acc)
    stripes = ((n - 1) - block_len * blocks) // _STRIPE_LEN
    for stripe in range(stripes):
        _accumulate_512(acc, data, blocks * block_len + stripe * _STRIPE_LEN,
                        stripe * _SECRET_CONSUME_RATE)
    _accumulate_512(acc, data, n - _STRIPE_LEN,
                    len(_SECRET) - _STRIPE_LEN - _SECRET_LASTACC_START)
    low = _merge(acc, _SECRET_MERGEACCS_START, (n * _P64_1) & _M64)
    high = _merge(acc, len(_SECRET) - 64 - _SECRET_MERGEACCS_START, ~(n * _P64_2) & _M64)
    return low, high


def xxh3_128(data: bytes) -> tuple[int, int]:
    """XXH3-128 of ``data`` with seed 0 and the default secret, as ``(low64, high64)``.

    >>> [hex(half) for half in xxh3_128(b"")]
    ['0x6001c324468d497f', '0x99aa06d3014798d8']
    """
    n = len(data)
    if n == 0:
        return (
            _avalanche64(_r64(_SECRET, 64) ^ _r64(_SECRET, 72)),
            _avalanche64(_r64(_SECRET, 80) ^ _r64(_SECRET, 88)),
        )
    if n <= 3:
        return _len_1to3(data)
    if n <= 8:
        return _len_4to8(data)
    if n <= 16:
        return _len_9to16(data)
    if n <= 128:
        return _len_17to128(data)
    if n <= _MIDSIZE_MAX:
        return _len_129to240(data)
    return _long(data)
