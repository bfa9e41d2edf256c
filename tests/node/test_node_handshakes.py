"""A peer with the wrong security mechanism or a wrong key never cuts the node off from its
driver: the failed handshake is logged once with the peer's address, counted in diagnostics,
and the legitimate driver is heard again (issue 21, fault 5). Over real 127.0.0.1 sockets,
both orders (a plain peer meeting a CURVE node, a CURVE peer meeting a plain node), both
topologies (the node connecting for scans, its default, and binding), and wrong keys refused
by ZAP."""

from __future__ import annotations

import contextlib
import logging
import time

import pytest
import zmq
from conftest import free_port, spinning_node
from test_node_hostile import frames, scene

from supportnode.bus import CurveKeys, Publisher, Subscriber, publisher_when_free
from supportnode.msgs import SupportSurfaces, decode_any

pytestmark = pytest.mark.skipif(not zmq.has("curve"), reason="libzmq without CURVE")


def _driver(node_keys, endpoint: str, node_binds: bool, curve: bool, pair: str = "driver"):
    """A scan publisher: binds when the node connects, connects when it binds."""
    made = node_keys["made"]
    ck = None
    if curve and node_binds:
        ck = CurveKeys(made / f"{pair}.key_secret", server_key=made / "node.key")
    elif curve:
        ck = CurveKeys(made / f"{pair}.key_secret", authorized_dir=node_keys["trusts_node"])
    if node_binds:
        return Publisher(endpoint, bind=False, curve=ck, hwm=1000)
    return publisher_when_free(endpoint, curve=ck, hwm=1000)


@contextlib.contextmanager
def _node(node_keys, endpoint: str, node_binds: bool, curve: bool):
    """A node (CURVE or plain) getting scans at ``endpoint``; yields a subscriber of its
    surfaces and diagnostics."""
    keys = {"curve_enabled": curve, "curve_keys_dir": str(node_keys["folder"]) if curve else ""}
    made = node_keys["made"]
    ck = CurveKeys(made / "client.key_secret", server_key=made / "node.key") if curve else None
    with spinning_node(
        scan_endpoint=endpoint, scan_bind=node_binds, pub_endpoint="tcp://127.0.0.1:*", **keys
    ) as (node, _):
        with Subscriber(
            node.pub_endpoint, ["surfaces", "diagnostics"], keep_newest=50, curve=ck
        ) as sub:
            yield sub


def _heard(pub: Publisher, sub: Subscriber, seconds: float) -> bool:
    """Scans from ``pub`` get results within ``seconds``."""
    pts = scene(4000)
    deadline = time.monotonic() + seconds
    stamp = time.time()
    while time.monotonic() < deadline:
        stamp += 0.1
        pub.send(frames(pts, stamp))
        t = time.monotonic() + 0.1
        while (f := sub.recv(max(0.0, t - time.monotonic()))) is not None:
            if isinstance(decode_any(f), SupportSurfaces):
                return True
    return False


def _counter(sub: Subscriber, name: str, want: int, seconds: float = 5.0) -> int:
    """The diagnostics counter ``name`` once it reaches ``want`` (or its last value)."""
    deadline, value = time.monotonic() + seconds, 0
    while time.monotonic() < deadline and value < want:
        f = sub.recv(0.1)
        if f is not None and (msg := decode_any(f)).TYPE == "Diagnostics":
            value = msg.counters.get(name, 0)
    return value


@pytest.mark.parametrize("node_binds", [False, True], ids=["node_connects", "node_binds"])
@pytest.mark.parametrize("node_curve", [True, False], ids=["curve_node", "plain_node"])
def test_wrong_mechanism_peer_then_the_right_driver_is_heard(
    node_keys, caplog, node_binds, node_curve
):
    endpoint = f"tcp://127.0.0.1:{free_port()}"
    with caplog.at_level(logging.WARNING, logger="supportnode.node"):
        with _node(node_keys, endpoint, node_binds, node_curve) as sub:
            with _driver(node_keys, endpoint, node_binds, curve=not node_curve) as wrong:
                assert not _heard(wrong, sub, 1.0)
                failures = _counter(sub, "handshake_failures_scans_mechanism", 1)
            with _driver(node_keys, endpoint, node_binds, curve=node_curve) as right:
                assert _heard(right, sub, 10.0), "the legitimate driver is not heard"
    assert failures >= 1
    lines = [r.getMessage() for r in caplog.records if "handshake with" in r.getMessage()]
    assert len(lines) == 1, lines  # once, though the wrong peer retried
    assert "security mechanism mismatch" in lines[0]
    # the peer's address: the endpoint when the node connects, the driver's port when it binds
    assert ("127.0.0.1:" + endpoint.rsplit(":", 1)[1]) in lines[0] or node_binds
    assert "127.0.0.1:" in lines[0] or "address gone" in lines[0]


def test_driver_with_a_key_not_authorised_is_refused_by_zap(node_keys, caplog):
    """The node binds for scans: a driver whose key is not in drivers/ is refused (ZAP),
    logged with its address and counted; the authorised driver is heard."""
    endpoint = f"tcp://127.0.0.1:{free_port()}"
    with caplog.at_level(logging.WARNING, logger="supportnode.node"):
        with _node(node_keys, endpoint, True, True) as sub:
            with _driver(node_keys, endpoint, True, True, pair="stranger") as stranger:
                assert not _heard(stranger, sub, 1.0)
                assert _counter(sub, "handshake_failures_scans_auth", 1) >= 1
            with _driver(node_keys, endpoint, True, True) as right:
                assert _heard(right, sub, 10.0)
    lines = [r.getMessage() for r in caplog.records if "its key was refused" in r.getMessage()]
    assert len(lines) == 1 and "127.0.0.1:" in lines[0], lines


def test_node_refused_by_its_driver_reconnects_once_the_driver_accepts_it(node_keys, tmp_path):
    """The node connects to a driver whose ZAP refuses the node's key (libzmq then ends the
    session for good); the driver restarts authorising it, and the node is heard again."""
    endpoint = f"tcp://127.0.0.1:{free_port()}"
    nobody = tmp_path / "nobody"
    nobody.mkdir()
    made = node_keys["made"]
    with _node(node_keys, endpoint, False, True) as sub:
        refusing = CurveKeys(made / "driver.key_secret", authorized_dir=nobody)
        with publisher_when_free(endpoint, curve=refusing, hwm=1000) as driver:
            assert not _heard(driver, sub, 1.0)
            assert _counter(sub, "handshake_failures_scans_auth", 1) >= 1
        with _driver(node_keys, endpoint, False, True) as driver:
            assert _heard(driver, sub, 10.0)
