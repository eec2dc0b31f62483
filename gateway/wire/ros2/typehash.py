"""Recomputing RIHS01 type hashes (REP 2011) from ``.msg`` definitions, without ROS.

The rule is that of ``rosidl_generator_type_description/__init__.py`` in the public repository
ros2/rosidl (``serialize_field_type``, ``extract_full_type_description``,
``calculate_type_hash``):

1. Each type becomes ``{"type_name": "pkg/msg/Name", "fields": [...]}``; a field is
   ``{"name", "type": {"type_id", "capacity", "string_capacity", "nested_type_name"}}``, with
   the ids of ``type_description_interfaces/msg/FieldType.msg`` (ros2/rcl_interfaces).  Default
   values, comments and constants do not take part.
2. The hashed object is ``{"type_description": <the type>, "referenced_type_descriptions":
   [<every type it references, directly or not, sorted by name>]}``.
3. ``json.dumps`` with ``separators=(", ", ": ")``, keys in the order above, ASCII only, then
   SHA-256 of the UTF-8 text; the hash string is ``RIHS01_`` and the hex digest.

The ``.msg`` reader here covers what ``rosidl_adapter`` turns into IDL for ordinary messages:
primitive types, (bounded) strings, fixed arrays, bounded and unbounded sequences, nested types
(``Type``, ``pkg/Type``; a service's parts as ``pkg/srv/Name_Request``), default values and
constants (both ignored).  Pure: no I/O.

:func:`complete_definition` writes the same definitions as one self-contained ``ros2msg``
schema, the form an MCAP file's ROS 2 channels carry (ros2/rosbag2,
``docs/message_definition_encoding.md``; the MCAP registry's ``ros2msg``).
"""

from __future__ import annotations

import enum
import hashlib
import json
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING

from gateway.core.errors import DecodeError
from gateway.wire.ros2.types import MESSAGE_DEFINITIONS, RIHS01_PREFIX

if TYPE_CHECKING:
    from collections.abc import Mapping


class FieldType(enum.IntEnum):
    """Scalar field type ids of ``type_description_interfaces/msg/FieldType.msg``."""

    NESTED_TYPE = 1
    INT8 = 2
    UINT8 = 3
    INT16 = 4
    UINT16 = 5
    INT32 = 6
    UINT32 = 7
    INT64 = 8
    UINT64 = 9
    FLOAT = 10
    DOUBLE = 11
    CHAR = 13
    WCHAR = 14
    BOOLEAN = 15
    BYTE = 16
    STRING = 17
    WSTRING = 18
    BOUNDED_STRING = 21
    BOUNDED_WSTRING = 22


#: Added to a scalar id for a fixed array, a bounded sequence, an unbounded sequence.
ARRAY_OFFSET = 48
BOUNDED_SEQUENCE_OFFSET = 96
UNBOUNDED_SEQUENCE_OFFSET = 144

#: ``.msg`` primitive -> field type, as ``rosidl_adapter`` maps them (``char`` is ``uint8``).
_PRIMITIVES = {
    "bool": FieldType.BOOLEAN, "byte": FieldType.BYTE, "char": FieldType.UINT8,
    "float32": FieldType.FLOAT, "float64": FieldType.DOUBLE,
    "int8": FieldType.INT8, "uint8": FieldType.UINT8, "int16": FieldType.INT16,
    "uint16": FieldType.UINT16, "int32": FieldType.INT32, "uint32": FieldType.UINT32,
    "int64": FieldType.INT64, "uint64": FieldType.UINT64,
    "string": FieldType.STRING, "wstring": FieldType.WSTRING,
}
_TYPE = re.compile(
    r"(?P<base>[A-Za-z][A-Za-z0-9_]*(?:/(?:srv/)?[A-Za-z][A-Za-z0-9_]*)?)"
    r"(?:<=(?P<string_bound>[0-9]+))?"
    r"(?:\[(?P<array>(?:<=)?[0-9]*)\])?$"
)
_NAME = re.compile(r"[a-z][a-z0-9_]*$")


@dataclass(frozen=True, slots=True)
class FieldDescription:
    """One field of a type description (``type_description_interfaces/msg/Field``).

    :param name: the field name.
    :param type_id: the ``FieldType`` id, array and sequence offsets included.
    :param capacity: array size or sequence bound, else 0.
    :param string_capacity: string bound, else 0.
    :param nested_type_name: ``pkg/msg/Name`` of a nested type, else ``""``.
    """

    name: str
    type_id: int
    capacity: int = 0
    string_capacity: int = 0
    nested_type_name: str = ""

    def as_json(self) -> dict[str, object]:
        """The hashed form: ``name`` then ``type`` (no default value)."""
        return {
            "name": self.name,
            "type": {
                "type_id": self.type_id,
                "capacity": self.capacity,
                "string_capacity": self.string_capacity,
                "nested_type_name": self.nested_type_name,
            },
        }


def _field(ros_name: str, line_no: int, type_text: str, name: str) -> FieldDescription:
    where = f"{ros_name} line {line_no}"
    match = _TYPE.match(type_text)
    if match is None or not _NAME.match(name):
        raise DecodeError(
            f"{where}: expected '<type> <field name>', got {type_text!r} {name!r}"
        )
    base = match["base"]
    bound = match["string_bound"]
    if base in _PRIMITIVES:
        type_id = int(_PRIMITIVES[base])
        nested = ""
        if bound is not None:
            if base not in ("string", "wstring"):
                raise DecodeError(f"{where}: expected a bound on a string, got {type_text!r}")
            type_id = int(FieldType.BOUNDED_STRING if base == "string"
                          else FieldType.BOUNDED_WSTRING)
    elif bound is None:
        type_id = int(FieldType.NESTED_TYPE)
        package = (base if "/" in base else ros_name).partition("/")[0]
        # (a service's parts, ``pkg/srv/Name_Request``, are named in full)
        nested = base if base.count("/") == 2 else f"{package}/msg/{base.rsplit('/', 1)[-1]}"
    else:
        raise DecodeError(f"{where}: expected a bound on a string, got {type_text!r}")
    capacity = 0
    array = match["array"]
    if array is not None:
        if array == "":
            type_id += UNBOUNDED_SEQUENCE_OFFSET
        elif array.startswith("<="):
            type_id += BOUNDED_SEQUENCE_OFFSET
            capacity = int(array[2:] or "0")
        else:
            type_id += ARRAY_OFFSET
            capacity = int(array)
        if array.startswith("<=") and capacity == 0:
            raise DecodeError(f"{where}: expected a sequence bound, got {type_text!r}")
    return FieldDescription(name, type_id, capacity, int(bound or 0), nested)


def parse_msg(ros_name: str, text: str) -> tuple[FieldDescription, ...]:
    """The fields of the ``.msg`` definition ``text`` of the type ``ros_name``.

    Comments (``#`` to the end of the line), blank lines, constants (``TYPE NAME=VALUE``) and
    default values are skipped.  A ``#`` inside a string default is not supported.

    :raises DecodeError: a line that is not a field or a constant.

    >>> parse_msg("std_msgs/msg/Header", "builtin_interfaces/Time stamp # when\\nstring frame_id")
    ... # doctest: +NORMALIZE_WHITESPACE
    (FieldDescription(name='stamp', type_id=1, capacity=0, string_capacity=0,
                      nested_type_name='builtin_interfaces/msg/Time'),
     FieldDescription(name='frame_id', type_id=17, capacity=0, string_capacity=0,
                      nested_type_name=''))
    """
    fields = []
    for line_no, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        parts = line.split(None, 1)
        if len(parts) < 2:
            raise DecodeError(
                f"{ros_name} line {line_no}: expected '<type> <field name>', got {raw!r}"
            )
        type_text, rest = parts
        head = re.split(r"[\s=]", rest, maxsplit=1)[0]
        if "=" in rest and rest[len(head):].lstrip().startswith("="):
            continue  # a constant
        fields.append(_field(ros_name, line_no, type_text, head))
    return tuple(fields)


def type_description(ros_name: str, definitions: Mapping[str, str] = MESSAGE_DEFINITIONS
                     ) -> dict[str, object]:
    """The hashed ``TypeDescription`` of ``ros_name``: the type and all it references.

    :param definitions: ``.msg`` text by ROS name; must hold every referenced type.
    :raises DecodeError: a missing or malformed definition.
    """
    parsed: dict[str, tuple[FieldDescription, ...]] = {}

    def fields_of(name: str) -> tuple[FieldDescription, ...]:
        if name not in parsed:
            if name not in definitions:
                raise DecodeError(
                    f"{ros_name}: expected a definition of {name}, got none among "
                    f"{sorted(definitions)}"
                )
            parsed[name] = parse_msg(name, definitions[name])
        return parsed[name]

    referenced: set[str] = set()
    queue = [f.nested_type_name for f in fields_of(ros_name) if f.nested_type_name]
    while queue:
        name = queue.pop()
        if name not in referenced:
            referenced.add(name)
            queue.extend(f.nested_type_name for f in fields_of(name) if f.nested_type_name)

    def individual(name: str) -> dict[str, object]:
        return {"type_name": name, "fields": [f.as_json() for f in fields_of(name)]}

    return {
        "type_description": individual(ros_name),
        "referenced_type_descriptions": [individual(n) for n in sorted(referenced)],
    }


def canonical_json(ros_name: str, definitions: Mapping[str, str] = MESSAGE_DEFINITIONS) -> str:
    """The exact text that is hashed (``json.dumps`` settings of ``calculate_type_hash``).

    >>> canonical_json("builtin_interfaces/msg/Time")[:60]
    '{"type_description": {"type_name": "builtin_interfaces/msg/T'
    """
    return json.dumps(
        type_description(ros_name, definitions),
        skipkeys=False,
        ensure_ascii=True,
        check_circular=True,
        allow_nan=False,
        indent=None,
        separators=(", ", ": "),
        sort_keys=False,
    )


def compute_type_hash(ros_name: str, definitions: Mapping[str, str] = MESSAGE_DEFINITIONS
                      ) -> str:
    """The RIHS01 hash string of ``ros_name``, recomputed from ``definitions``.

    >>> compute_type_hash("builtin_interfaces/msg/Time")
    'RIHS01_b106235e25a4c5ed35098aa0a61a3ee9c9b18d197f398b0e4206cea9acf9c197'
    """
    digest = hashlib.sha256(canonical_json(ros_name, definitions).encode("utf-8"))
    return RIHS01_PREFIX + digest.hexdigest()


#: The first line of the two that precede each dependency in a ``ros2msg`` schema.
MSG_DELIMITER = "=" * 80


def complete_definition(ros_name: str, definitions: Mapping[str, str] = MESSAGE_DEFINITIONS
                        ) -> str:
    """The ``ros2msg`` schema of ``ros_name``: its ``.msg`` text first, then that of every type
    it references (directly or not, sorted by name), each after a line of 80 ``=`` and a line
    ``MSG: <its full ROS name>``.

    >>> print(complete_definition("std_msgs/msg/Header").replace("=" * 80, "=" * 8))
    builtin_interfaces/Time stamp
    string frame_id
    ========
    MSG: builtin_interfaces/msg/Time
    int32 sec
    uint32 nanosec
    <BLANKLINE>

    :raises DecodeError: a missing or malformed definition.
    """
    described = type_description(ros_name, definitions)
    referenced = described["referenced_type_descriptions"]
    assert isinstance(referenced, list)
    parts = [definitions[ros_name]]
    parts += [f"{MSG_DELIMITER}\nMSG: {ref['type_name']}\n{definitions[ref['type_name']]}"
              for ref in referenced]
    return "".join(parts)
