"""CURVE on the bus: authorised clients receive, others (wrong key, no CURVE) get nothing,
key-file errors are one line, `supportnode keys` writes a key pair, the node wires its keys."""

from __future__ import annotations

import dataclasses
import os
import shutil
import time
from pathlib import Path

import pytest
import zmq

from supportnode.bus import BusError, CurveKeys, Publisher, Subscriber
from supportnode.cli import main
from supportnode.node.node import Node
from supportnode.params import DetectParams

pytestmark = pytest.mark.skipif(not zmq.has("curve"), reason="libzmq without CURVE")


@pytest.fixture
def keys(tmp_path: Path) -> dict[str, Path]:
    """Server pair, an authorised client pair (public key in allowed/), a stranger pair."""
    import zmq.auth

    made = tmp_path / "made"
    allowed = tmp_path / "allowed"
    made.mkdir()
    allowed.mkdir()
    for name in ("server", "client", "stranger"):
        zmq.auth.create_certificates(made, name)
    shutil.copy(made / "client.key", allowed / "client.key")
    return {"made": made, "allowed": allowed}


def _server_keys(k: dict[str, Path]) -> CurveKeys:
    return CurveKeys(key_file=k["made"] / "server.key_secret", authorized_dir=k["allowed"])


def _client_keys(k: dict[str, Path], name: str) -> CurveKeys:
    return CurveKeys(key_file=k["made"] / f"{name}.key_secret", server_key=k["made"] / "server.key")


def _gets_through(pub: Publisher, sub: Subscriber, seconds: float) -> bool:
    """Publish probes for up to ``seconds``; True as soon as one arrives."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        pub.send([b"scan", b"probe"])
        if sub.recv(0.02) is not None:
            return True
    return False


def test_authorised_client_receives(keys):
    with (
        Publisher("tcp://127.0.0.1:*", curve=_server_keys(keys)) as pub,
        Subscriber(pub.endpoint, "scan", curve=_client_keys(keys, "client")) as sub,
    ):
        assert _gets_through(pub, sub, 5.0)
        pub.send([b"scan", b"secret payload"])
        frames = sub.recv(2.0)
        while frames is not None and bytes(frames[1]) == b"probe":
            frames = sub.recv(2.0)
    assert frames is not None and bytes(frames[1]) == b"secret payload"


def test_subscriber_can_be_the_server(keys):
    with (
        Subscriber("tcp://127.0.0.1:*", "scan", bind=True, curve=_server_keys(keys)) as sub,
        Publisher(sub.endpoint, bind=False, curve=_client_keys(keys, "client")) as pub,
    ):
        assert _gets_through(pub, sub, 5.0)


def test_unauthorised_and_plain_clients_receive_nothing(keys):
    with (
        Publisher("tcp://127.0.0.1:*", curve=_server_keys(keys)) as pub,
        Subscriber(pub.endpoint, "scan", curve=_client_keys(keys, "stranger")) as stranger,
        Subscriber(pub.endpoint, "scan") as plain,
        Subscriber(pub.endpoint, "scan", curve=_client_keys(keys, "client")) as friend,
    ):
        # The authorised client proves the server is up and publishing meanwhile.
        assert _gets_through(pub, friend, 5.0)
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline:
            pub.send([b"scan", b"probe"])
            time.sleep(0.02)
        assert stranger.recv(0.2) is None and stranger.received == 0
        assert plain.recv(0.2) is None and plain.received == 0


def test_two_servers_in_one_context_keep_their_own_allowed_keys(keys, tmp_path):
    other = tmp_path / "other"
    other.mkdir()
    shutil.copy(keys["made"] / "stranger.key", other / "stranger.key")
    with (
        Publisher("tcp://127.0.0.1:*", curve=_server_keys(keys)) as a,
        Publisher(
            "tcp://127.0.0.1:*",
            curve=CurveKeys(keys["made"] / "server.key_secret", authorized_dir=other),
        ) as b,
        Subscriber(a.endpoint, "scan", curve=_client_keys(keys, "stranger")) as sa,
        Subscriber(b.endpoint, "scan", curve=_client_keys(keys, "stranger")) as sb,
    ):
        assert _gets_through(b, sb, 5.0)
        assert not _gets_through(a, sa, 0.5)


def test_missing_key_files_are_one_line_errors(keys):
    missing = keys["made"] / "nope.key_secret"
    with pytest.raises(BusError) as err:
        Publisher("tcp://127.0.0.1:*", curve=CurveKeys(missing, authorized_dir=keys["allowed"]))
    assert str(missing) in str(err.value) and "\n" not in str(err.value)
    # A client given a public key file where its secret is needed.
    with pytest.raises(BusError, match="no secret key"):
        Subscriber(
            "tcp://127.0.0.1:5999",
            "scan",
            curve=CurveKeys(keys["made"] / "client.key", server_key=keys["made"] / "server.key"),
        )
    with pytest.raises(BusError, match="not found"):
        Subscriber(
            "tcp://127.0.0.1:5999",
            "scan",
            curve=CurveKeys(keys["made"] / "client.key_secret", server_key=missing),
        )
    with pytest.raises(BusError, match="folder not found"):
        Publisher(
            "tcp://127.0.0.1:*",
            curve=CurveKeys(keys["made"] / "server.key_secret", authorized_dir=missing),
        )


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads any file")
def test_unreadable_key_file(keys):
    secret = keys["made"] / "server.key_secret"
    secret.chmod(0)
    with pytest.raises(BusError, match="cannot read") as err:
        Publisher("tcp://127.0.0.1:*", curve=_server_keys(keys))
    assert str(secret) in str(err.value)


def test_keys_command_writes_a_pair(tmp_path, capsys):
    assert main(["keys", str(tmp_path / "k"), "--name", "robot"]) == 0
    assert (tmp_path / "k" / "robot.key").is_file()
    assert (tmp_path / "k" / "robot.key_secret").is_file()
    assert "robot.key" in capsys.readouterr().out
    assert main(["keys", str(tmp_path / "k"), "--name", "robot"]) == 2  # no silent overwrite


def _node_folder(keys, tmp_path, subscribers=("client",)) -> Path:
    """A node key folder in the documented layout (`supportnode.curve`); the scan driver's
    pair is "stranger"."""
    folder = tmp_path / "node"
    (folder / "subscribers").mkdir(parents=True)
    for name in ("server.key_secret", "server.key"):
        shutil.copy(keys["made"] / name, folder / name)
    for name in subscribers:
        shutil.copy(keys["made"] / f"{name}.key", folder / "subscribers" / f"{name}.key")
    shutil.copy(keys["made"] / "stranger.key", folder / "scan_server.key")
    return folder


def _curve_node(folder: Path, **node_keys) -> Node:
    params = DetectParams()
    node_params = dataclasses.replace(
        params.node,
        curve_enabled=True,
        curve_keys_dir=str(folder),
        pub_endpoint="tcp://127.0.0.1:*",
        # nothing listens on port 9 (discard): a connecting scan socket just waits
        scan_endpoint="tcp://127.0.0.1:*" if node_keys.get("scan_bind") else "tcp://127.0.0.1:9",
        **node_keys,
    )
    return Node(dataclasses.replace(params, node=node_params))


def test_node_publishes_only_to_authorised_clients(keys, tmp_path):
    """The key folder's own keys authorise nobody: the scan driver's pair (its public key is
    the folder's scan_server.key) cannot subscribe to results; a subscriber in subscribers/
    can; the node's own pair cannot either."""
    folder = _node_folder(keys, tmp_path)
    with _curve_node(folder) as node:
        node.open()
        assert node._sockets.pub is not None
        with (
            Subscriber(node.pub_endpoint, "scan", curve=_client_keys(keys, "client")) as sub,
            Subscriber(node.pub_endpoint, "scan", curve=_client_keys(keys, "stranger")) as drv,
            Subscriber(node.pub_endpoint, "scan", curve=_client_keys(keys, "server")) as own,
        ):
            assert _gets_through(node._sockets.pub, sub, 5.0)
            assert not _gets_through(node._sockets.pub, drv, 0.5)
            assert not _gets_through(node._sockets.pub, own, 0.2)
            deadline = time.monotonic() + 3
            while time.monotonic() < deadline:  # the refusals are counted by the node
                if node.diagnostics().counters.get("handshake_failures_results_auth", 0) >= 2:
                    break
                time.sleep(0.05)
            assert node.diagnostics().counters["handshake_failures_results_auth"] >= 2


def test_node_binding_for_scans_takes_drivers_from_their_folder(keys, tmp_path):
    folder = _node_folder(keys, tmp_path)
    (folder / "drivers").mkdir()
    shutil.copy(keys["made"] / "stranger.key", folder / "drivers" / "stranger.key")
    with _curve_node(folder, scan_bind=True) as node:
        node.open()
        assert node._sub is not None
        with Publisher(node.scan_endpoint, bind=False, curve=_client_keys(keys, "stranger")) as p:
            deadline = time.monotonic() + 5.0
            while node._sub.received == 0 and time.monotonic() < deadline:
                p.send([b"scan", b"probe"])  # reaches the node, which rejects it as malformed
                node._sub.recv(0.02)
            assert node._sub.received > 0


def test_old_key_folder_layout_is_a_one_line_error(keys, tmp_path):
    """Client keys beside the node's own (the old layout) authorised its own pairs too."""
    folder = _node_folder(keys, tmp_path)
    shutil.copy(keys["made"] / "client.key", folder / "client.key")
    with _curve_node(folder) as node, pytest.raises(BusError) as err:
        node.open()
    text = str(err.value)
    assert "client.key" in text and "subscribers/" in text and "drivers/" in text
    assert "\n" not in text
    assert main(["run", "--set", "node.curve_enabled=true", "--set",
                 f"node.curve_keys_dir={folder}", "--duration", "0.1"]) == 2  # fmt: skip


def test_node_curve_without_folder_is_an_error():
    params = DetectParams()
    node_params = dataclasses.replace(
        params.node, curve_enabled=True, pub_endpoint="tcp://127.0.0.1:*"
    )
    with Node(dataclasses.replace(params, node=node_params)) as node:
        with pytest.raises(BusError, match="curve_keys_dir"):
            node.open()
