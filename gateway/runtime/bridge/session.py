"""The bridge's Zenoh session, configured from the ``bridge.zenoh`` block.

Zenoh's defaults suit a laptop, not a robot: a peer listens on every interface on a random port
(``tcp/[::]:0``) and announces itself by UDP multicast.  Here nothing listens unless ``listen``
names an endpoint, multicast scouting is off unless asked for, and the gateway's lease (how
long its peers keep it and its liveliness tokens alive when it falls silent; each peer is
judged by the lease it announces itself, so a frozen commander by its own) is the block's.
Configuration keys: https://github.com/eclipse-zenoh/zenoh/blob/main/DEFAULT_CONFIG.json5
(``mode``, ``listen/endpoints``, ``connect/endpoints``, ``scouting/multicast/enabled``,
``transport/link/tx/lease`` in ms).
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

from gateway.core.errors import GatewayError

if TYPE_CHECKING:
    import zenoh

    from gateway.core.bridge_settings import ZenohSettings

__all__ = ["INSTALL_HINT", "BridgeError", "import_zenoh", "open_session", "session_config"]

INSTALL_HINT = "install the extra: pip install 'wheelgate[zenoh]'"


class BridgeError(GatewayError):
    """The bridge cannot start or run (Zenoh missing, an endpoint that cannot be opened)."""


def import_zenoh() -> object:
    """The ``zenoh`` module.

    :raises BridgeError: when it is not installed, saying how to install it.
    """
    try:
        import zenoh  # noqa: PLC0415 - optional, imported only with a bridge: block
    except ImportError as err:
        raise BridgeError(f"bridge: the zenoh package is not installed ({err}); "
                          f"{INSTALL_HINT}") from err
    return zenoh


def session_config(settings: ZenohSettings) -> dict[str, object]:
    """The Zenoh configuration keys this bridge sets, as JSON values (see the module's doc)."""
    return {
        "mode": settings.mode.value,
        "listen/endpoints": list(settings.listen),
        "connect/endpoints": list(settings.connect),
        "scouting/multicast/enabled": settings.multicast_scouting,
        "transport/link/tx/lease": round(settings.lease_s * 1000),
    }


def open_session(settings: ZenohSettings) -> zenoh.Session:
    """A Zenoh session with exactly these settings.

    :raises BridgeError: when Zenoh is missing or the session cannot be opened (an endpoint in
        use or not reachable), naming the endpoints.
    """
    import_zenoh()
    import zenoh  # noqa: PLC0415 - see import_zenoh

    config = zenoh.Config()
    for key, value in session_config(settings).items():
        config.insert_json5(key, json.dumps(value))
    try:
        return zenoh.open(config)
    except zenoh.ZError as err:
        raise BridgeError(
            f"bridge.zenoh: cannot open the session (mode {settings.mode.value}, listen "
            f"{list(settings.listen)}, connect {list(settings.connect)}): {err}"
        ) from err
