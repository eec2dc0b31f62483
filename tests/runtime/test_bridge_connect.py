"""A bridge in client mode whose router is not up yet: the gateway starts without it, and the
bridge connects and declares its keys once the router is there (a robot may boot before the
machine that runs the router).  Real Zenoh sessions on the loopback, free ports."""

from __future__ import annotations

import sys
import time
from typing import Any

import pytest

from gateway.core.bridge_settings import BridgeSettings, ZenohMode, ZenohSettings
from gateway.runtime.bridge import bridge as bridge_module
from gateway.runtime.bridge.bridge import Bridge
from gateway.runtime.bridge.native import NativeKeys
from gateway.runtime.bridge.session import BridgeError, open_session
from tests.conftest import REPO

sys.path.insert(0, str(REPO / "tools"))
from bridge_peer import free_port

pytest.importorskip("zenoh", reason="eclipse-zenoh not installed: pip install 'wheelgate[zenoh]'")
pytestmark = pytest.mark.timeout(60)


def _router(endpoint: str) -> Any:
    return open_session(ZenohSettings(ZenohMode.PEER, listen=(endpoint,)))


def _token_seen(session: Any, key: str) -> bool:
    return any(True for _ in session.liveliness().get(key, timeout=1.0))


def test_a_client_whose_router_is_not_up_connects_when_it_comes(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bridge_module, "CONNECT_FIRST_S", 0.2)
    monkeypatch.setattr(bridge_module, "CONNECT_MAX_S", 0.5)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    settings = BridgeSettings(ZenohSettings(ZenohMode.CLIENT, connect=(endpoint,)), "robot1")
    bridge = Bridge(settings)  # no router: no error, the gateway would run on
    try:
        assert bridge.session is None
        assert bridge.take_twists() == [] and bridge.take() is None
        time.sleep(1.0)  # a few failed tries
        router = _router(endpoint)
        try:
            key = NativeKeys.of("robot1").gateway_token
            end = time.monotonic() + 30
            while not _token_seen(router, key):
                assert time.monotonic() < end, "the bridge never connected"
                time.sleep(0.2)
            assert bridge.session is not None
        finally:
            bridge.close()
            router.close()
    finally:
        bridge.close()


def test_closing_a_bridge_that_never_connected_stops_its_tries(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(bridge_module, "CONNECT_FIRST_S", 0.1)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    bridge = Bridge(BridgeSettings(ZenohSettings(ZenohMode.CLIENT, connect=(endpoint,)), "r"))
    bridge.close()
    router = _router(endpoint)  # a router that comes after the close sees no gateway
    try:
        time.sleep(1.0)
        assert bridge.session is None
        assert not _token_seen(router, NativeKeys.of("r").gateway_token)
    finally:
        router.close()


def test_a_peer_that_cannot_listen_is_still_an_error() -> None:
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    holder = _router(endpoint)
    try:
        with pytest.raises(BridgeError, match="cannot open the session"):
            Bridge(BridgeSettings(ZenohSettings(ZenohMode.PEER, listen=(endpoint,)), "r"))
    finally:
        holder.close()
