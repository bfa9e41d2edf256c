"""The tools take the CURVE options (--curve-key, --curve-server-key, --curve-authorized):
echo, hz and record hear a CURVE node with keys, and without them say why they hear nothing;
play feeds a CURVE node; options that do not fit together are one-line errors."""

from __future__ import annotations

import contextlib
import time

import pytest
import zmq
from conftest import REPO, free_port, spinning_node

from supportnode.cli import main
from supportnode.io.recording import McapFile

pytestmark = pytest.mark.skipif(not zmq.has("curve"), reason="libzmq without CURVE")
RECORDING = REPO / "sim_scans" / "table_chairs_lidar.mcap"


@contextlib.contextmanager
def _curve_node(node_keys, scan_endpoint: str = "tcp://127.0.0.1:9"):
    with spinning_node(
        scan_endpoint=scan_endpoint,
        pub_endpoint=f"tcp://127.0.0.1:{free_port()}",
        curve_enabled=True,
        curve_keys_dir=str(node_keys["folder"]),
    ) as (node, _):
        yield node


def _client(node_keys) -> list[str]:
    made = node_keys["made"]
    return ["--curve-key", str(made / "client.key_secret"), "--curve-server-key", str(made / "node.key")]  # fmt: skip


@pytest.mark.parametrize("command", ["echo", "hz"])
def test_echo_and_hz_without_keys_say_why_they_hear_nothing(node_keys, capsys, command):
    with _curve_node(node_keys) as node:
        limit = ["--timeout", "2"] if command == "echo" else ["--duration", "2"]
        assert main([command, "diagnostics", "--endpoint", node.pub_endpoint, *limit]) == 0
    err = capsys.readouterr().err
    assert f"supportnode {command}: subscriber {node.pub_endpoint}: handshake" in err
    assert "security mechanism mismatch" in err and "no security (plain)" in err
    assert err.count("handshake with") == 1  # once, though it reconnects


def test_echo_hz_and_record_with_keys_hear_the_node(node_keys, capsys, tmp_path):
    with _curve_node(node_keys) as node:
        ep = node.pub_endpoint
        assert main(["echo", "diagnostics", "--endpoint", ep, "--count", "1", "--timeout", "10", *_client(node_keys)]) == 0  # fmt: skip
        out = capsys.readouterr().out
        assert "type: Diagnostics" in out
        assert main(["hz", "diagnostics", "--endpoint", ep, "--duration", "1.5", *_client(node_keys)]) == 0  # fmt: skip
        assert "rate " in capsys.readouterr().out
        rec = tmp_path / "d.mcap"
        assert main(["record", "diagnostics", "-o", str(rec), "--endpoint", ep, "--duration", "1.5", "--quiet", *_client(node_keys)]) == 0  # fmt: skip
    with McapFile(rec) as f:
        assert sum(1 for m in f.messages() if m.channel.topic == "diagnostics") >= 2


def test_play_feeds_a_curve_node(node_keys, capsys):
    endpoint = f"tcp://127.0.0.1:{free_port()}"
    made = node_keys["made"]
    driver = ["--curve-key", str(made / "driver.key_secret"), "--curve-authorized", str(node_keys["trusts_node"])]  # fmt: skip
    with _curve_node(node_keys, endpoint) as node:
        args = ["play", str(RECORDING), "--endpoint", endpoint, "--duration", "2", "--quiet"]
        assert main([*args, *driver]) == 0
        deadline = time.monotonic() + 5
        while node.diagnostics().counters["scans_processed"] == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert node.diagnostics().counters["scans_processed"] > 0


@pytest.mark.parametrize(
    ("extra", "needle"),
    [
        (["--curve-server-key", "x.key"], "need --curve-key"),
        (["--curve-key", "x.key_secret"], "needs --curve-server-key"),
        (["--curve-key", "missing.key_secret", "--curve-server-key", "x.key"], "not found"),
    ],
)
def test_curve_options_that_do_not_fit_are_one_line_errors(capsys, extra, needle):
    assert main(["echo", "diagnostics", "--endpoint", "tcp://127.0.0.1:9", *extra]) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1
