"""ROS 2 topic, namespace and node names: validation and resolution to fully qualified names.

The rules are those of the ROS 2 design article "Topic and Service name mapping to DDS"
(design.ros2.org, ``topic_and_service_names``) as ``rmw`` enforces them
(``rmw/src/validate_full_topic_name.c``, ``validate_namespace.c``, ``validate_node_name.c`` in
the public repository ros2/rmw):

* a name is made of tokens of letters, digits and ``_``, separated by single ``/``;
* no token starts with a digit; no empty token (no ``//``); no trailing ``/``;
* a fully qualified topic name starts with ``/`` and is at most 247 characters, a namespace
  at most 245; a node name is one token of at most 255 characters.

Private (``~``) names and substitutions (``{node}``) are not supported: the bridge takes its
names from configuration, where they would only hide a mistake.  Errors are
:class:`~gateway.core.errors.ConfigError` naming the thing, what was expected and what came.
Pure: no I/O.
"""

from __future__ import annotations

import re

from gateway.core.errors import ConfigError

#: ``RMW_TOPIC_MAX_NAME_LENGTH`` (255 less 8 reserved for prefixes).
MAX_TOPIC_NAME_LENGTH = 247
#: ``RMW_NAMESPACE_MAX_LENGTH``.
MAX_NAMESPACE_LENGTH = MAX_TOPIC_NAME_LENGTH - 2
#: ``RMW_NODE_NAME_MAX_NAME_LENGTH``.
MAX_NODE_NAME_LENGTH = 255

_TOKEN = re.compile(r"[A-Za-z0-9_]+")
_RULES = 'letters, digits and "_" in tokens separated by single "/", no token starting with a digit'


def _check_tokens(what: str, name: str, tokens: list[str]) -> None:
    for token in tokens:
        if token == "":
            raise ConfigError(f'{what}: expected {_RULES}, got {name!r} (it has "//")')
        if not _TOKEN.fullmatch(token):
            bad = next(c for c in token if not (c.isascii() and (c.isalnum() or c == "_")))
            hint = " (private and substituted names are not supported)" if bad in "~{}" else ""
            raise ConfigError(
                f"{what}: expected {_RULES}, got {name!r} (character {bad!r}){hint}"
            )
        if token[0].isdigit():
            raise ConfigError(
                f"{what}: expected {_RULES}, got {name!r} (token {token!r} starts with a digit)"
            )


def validate_topic_name(name: str, what: str = "topic name") -> str:
    """``name`` if it is a valid relative (``cmd_vel``) or absolute (``/cmd_vel``) topic name.

    :param what: what the name is, for the error message (a configuration key path).
    :raises ConfigError: an invalid name.
    """
    if not isinstance(name, str) or name in ("", "/"):
        raise ConfigError(f"{what}: expected a topic name such as 'cmd_vel', got {name!r}")
    if name.endswith("/"):
        raise ConfigError(f"{what}: expected no trailing '/', got {name!r}")
    body = name[1:] if name.startswith("/") else name
    _check_tokens(what, name, body.split("/"))
    return name


def validate_namespace(namespace: str, what: str = "namespace") -> str:
    """The absolute form of ``namespace``: ``""`` and ``"/"`` give ``"/"``, ``robot1`` gives
    ``/robot1`` (as ``rclcpp`` and ``rclpy`` complete a relative namespace).

    :raises ConfigError: an invalid namespace.

    >>> validate_namespace("robot1")
    '/robot1'
    """
    if not isinstance(namespace, str):
        raise ConfigError(f"{what}: expected a namespace such as '/robot1', got {namespace!r}")
    if namespace in ("", "/"):
        return "/"
    absolute = namespace if namespace.startswith("/") else "/" + namespace
    if absolute.endswith("/"):
        raise ConfigError(f"{what}: expected no trailing '/', got {namespace!r}")
    _check_tokens(what, namespace, absolute[1:].split("/"))
    if len(absolute) > MAX_NAMESPACE_LENGTH:
        raise ConfigError(
            f"{what}: expected at most {MAX_NAMESPACE_LENGTH} characters, "
            f"got {len(absolute)} in {namespace!r}"
        )
    return absolute


def validate_node_name(name: str, what: str = "node name") -> str:
    """``name`` if it is a valid node name (one token, no ``/``).

    :raises ConfigError: an invalid node name.
    """
    if not isinstance(name, str) or name == "":
        raise ConfigError(f"{what}: expected a node name such as 'wheelgate', got {name!r}")
    if "/" in name:
        raise ConfigError(f"{what}: expected a node name without '/', got {name!r}")
    _check_tokens(what, name, [name])
    if len(name) > MAX_NODE_NAME_LENGTH:
        raise ConfigError(
            f"{what}: expected at most {MAX_NODE_NAME_LENGTH} characters, got {len(name)}"
        )
    return name


def resolve_topic_name(name: str, namespace: str = "/", what: str = "topic name") -> str:
    """The fully qualified name of topic ``name`` in ``namespace``.

    An absolute name stays as it is; a relative one goes under the namespace.

    :raises ConfigError: an invalid name or namespace, or a result longer than 247 characters.

    >>> resolve_topic_name("cmd_vel", "robot1")
    '/robot1/cmd_vel'
    >>> resolve_topic_name("/tf", "/robot1")
    '/tf'
    """
    validate_topic_name(name, what)
    if name.startswith("/"):
        full = name
    else:
        ns = validate_namespace(namespace, f"namespace of {what}")
        full = (ns if ns == "/" else ns + "/") + name
    if len(full) > MAX_TOPIC_NAME_LENGTH:
        raise ConfigError(
            f"{what}: expected at most {MAX_TOPIC_NAME_LENGTH} characters fully qualified, "
            f"got {len(full)} in {full!r}"
        )
    return full


def validate_full_topic_name(name: str, what: str = "topic name") -> str:
    """``name`` if it is a valid fully qualified topic name (starting with ``/``).

    :raises ConfigError: otherwise.
    """
    if not isinstance(name, str) or not name.startswith("/"):
        raise ConfigError(f"{what}: expected a fully qualified name such as '/cmd_vel', "
                          f"got {name!r}")
    return resolve_topic_name(name, "/", what)
