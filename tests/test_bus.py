"""ZeroMQ transport: round trips on 127.0.0.1, exact topics, keep-newest drops, endpoint errors."""

from __future__ import annotations

import time

import pytest
import zmq

from supportnode.bus import BusError, Publisher, Subscriber, check_endpoint
from supportnode.errors import SupportNodeError


def _connected(pub: Publisher, sub: Subscriber, topic: bytes = b"scan") -> None:
    """Send probes until the subscription has reached the publisher (ZeroMQ's slow joiner:
    messages published before that are lost), then discard the probes."""
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline:
        pub.send([topic, b"probe"])
        if sub.recv(0.02) is not None:
            while sub.recv(0.02) is not None:
                pass
            sub.dropped = 0
            return
    raise AssertionError("subscriber never connected")


def test_round_trip_tcp_random_port():
    with Publisher("tcp://127.0.0.1:*") as pub:
        assert pub.endpoint.startswith("tcp://127.0.0.1:") and not pub.endpoint.endswith("*")
        with Subscriber(pub.endpoint, "scan") as sub:
            _connected(pub, sub)
            payload = bytes(range(256)) * 1000
            pub.send([b"scan", b"header", memoryview(payload)])
            frames = sub.recv(2.0)
    assert frames is not None
    assert frames[0] == b"scan"
    assert bytes(frames[1]) == b"header"
    assert bytes(frames[2]) == payload
    assert sub.closed and pub.closed


def test_subscriber_binds_publisher_connects():
    with Subscriber("tcp://127.0.0.1:*", ["scan"], bind=True) as sub:
        with Publisher(sub.endpoint, bind=False) as pub:
            _connected(pub, sub)
            pub.send([b"scan", b"x"])
            frames = sub.recv(2.0)
    assert frames is not None and bytes(frames[1]) == b"x"


def test_topic_filter_is_exact():
    with (
        Publisher("tcp://127.0.0.1:*") as pub,
        Subscriber(pub.endpoint, "scan", keep_newest=10) as sub,
    ):
        _connected(pub, sub)
        pub.send([b"scan2", b"no"])
        pub.send([b"sc", b"no"])
        pub.send([b"scan", b"yes"])
        first = sub.recv(2.0)
        assert first is not None and first[0] == b"scan" and bytes(first[1]) == b"yes"
        assert sub.recv(0.1) is None
        assert sub.dropped == 0


def test_several_topics():
    with (
        Publisher("tcp://127.0.0.1:*") as pub,
        Subscriber(pub.endpoint, ["a", b"b"], keep_newest=5) as sub,
    ):
        _connected(pub, sub, b"a")
        for topic in (b"a", b"c", b"b"):
            pub.send([topic, topic])
        got = [sub.recv(1.0), sub.recv(1.0)]
        assert [f[0] for f in got if f] == [b"a", b"b"]


@pytest.mark.parametrize("keep", [1, 3])
def test_keep_newest_drops_old_messages(keep):
    with (
        Publisher("tcp://127.0.0.1:*") as pub,
        Subscriber(pub.endpoint, "scan", keep_newest=keep) as sub,
    ):
        _connected(pub, sub)
        n = 20
        for i in range(n):
            pub.send([b"scan", str(i).encode()])
        # A slow consumer: everything has arrived (or been dropped in ZeroMQ's queues) by now.
        time.sleep(0.2)
        got = []
        while (frames := sub.recv(0.1)) is not None:
            got.append(int(bytes(frames[1])))
    # The newest message always survives, in order; every message is received or counted
    # unless ZeroMQ's own small queue dropped it (uncountable by design).
    assert got[-1] == n - 1
    assert got == sorted(got) and 1 <= len(got) <= keep
    assert sub.dropped >= 1
    assert len(got) + sub.dropped <= n


def test_refused_messages_do_not_push_out_the_newest_good_one():
    """A check refuses malformed messages as they come off the socket: a scan followed by
    garbage is kept (keep_newest=1), the garbage is counted as refused, not the scan as
    dropped; recv returns what the check made of the message."""
    seen = []

    def parse(frames):
        payload = bytes(frames[1])
        seen.append(payload)
        return payload.decode() if payload == b"probe" or payload.isdigit() else None

    with (
        Publisher("tcp://127.0.0.1:*") as pub,
        Subscriber(pub.endpoint, "scan", keep_newest=1, check=parse) as sub,
    ):
        _connected(pub, sub)
        for i in range(3):
            pub.send([b"scan", str(i).encode()])
            pub.send([b"scan", b"\xc1 not a scan"])
            pub.send([b"scan", b""])
        time.sleep(0.2)  # all of it has arrived: the consumer was busy
        got = []
        while (item := sub.recv(0.1)) is not None:
            got.append(item)
    assert got == ["2"]
    assert sub.refused == 6 and sub.dropped == 2  # scans 0 and 1: older good ones
    assert seen.count(b"\xc1 not a scan") == 3


def test_recv_timeout_returns_none_promptly():
    with Subscriber("inproc://nothing-here", "scan") as sub:
        t0 = time.monotonic()
        assert sub.recv(0.05) is None
        assert time.monotonic() - t0 < 0.5
        assert sub.recv(0) is None


def test_recv_returns_when_its_wake_descriptor_is_readable():
    """A wait on the socket and on another descriptor: None as soon as that one is readable
    (well before the timeout), the message first when both are ready."""
    import socket

    a, b = socket.socketpair()
    with Publisher("inproc://wake", "scan") as pub, Subscriber("inproc://wake", "scan") as sub:
        time.sleep(0.1)
        t0 = time.monotonic()
        assert sub.recv(0.1, wake=a.fileno()) is None  # nothing rang: the whole timeout
        assert time.monotonic() - t0 >= 0.09
        b.send(b"x")
        t0 = time.monotonic()
        assert sub.recv(5.0, wake=a.fileno()) is None
        assert time.monotonic() - t0 < 1.0
        pub.send([b"scan", b"1"])
        time.sleep(0.05)
        assert bytes(sub.recv(5.0, wake=a.fileno())[1]) == b"1"  # still rung: messages first
    a.close()
    b.close()


def test_inproc_shared_context():
    ctx = zmq.Context()
    try:
        with (
            Publisher("inproc://bus-test", context=ctx) as pub,
            Subscriber("inproc://bus-test", "t", context=ctx) as sub,
        ):
            _connected(pub, sub, b"t")
            pub.send([b"t", b"inproc"])
            frames = sub.recv(1.0)
            assert frames is not None and bytes(frames[1]) == b"inproc"
    finally:
        ctx.term()


def test_ipc_endpoint(tmp_path):
    endpoint = f"ipc://{tmp_path}/bus.sock"
    with Publisher(endpoint) as pub, Subscriber(endpoint, "t") as sub:
        _connected(pub, sub, b"t")
        pub.send([b"t", b"ipc"])
        frames = sub.recv(1.0)
    assert frames is not None and bytes(frames[1]) == b"ipc"


def test_oversized_messages_are_discarded():
    with (
        Publisher("tcp://127.0.0.1:*") as pub,
        Subscriber(pub.endpoint, "t", keep_newest=5, max_message_bytes=1000) as sub,
    ):
        _connected(pub, sub, b"t")
        pub.send([b"t", b"a" * 500, b"b" * 600])  # each frame fits, the message does not
        pub.send([b"t", b"small"])
        frames = sub.recv(1.0)
        assert frames is not None and bytes(frames[1]) == b"small"
        assert sub.oversized == 1


def test_address_in_use_names_the_endpoint():
    with Publisher("tcp://127.0.0.1:*") as first:
        with pytest.raises(BusError, match=rf"^{first.endpoint}: address already in use$"):
            Publisher(first.endpoint)
        assert issubclass(BusError, SupportNodeError)


@pytest.mark.parametrize(
    "endpoint, message",
    [
        ("udp://127.0.0.1:5", "unsupported endpoint"),
        ("127.0.0.1:5556", "unsupported endpoint"),
        ("tcp://127.0.0.1", "without a port"),
        ("tcp://300.1.1.1:5556", "tcp://300.1.1.1:5556: cannot bind"),
    ],
)
def test_bad_endpoints(endpoint, message):
    with pytest.raises(BusError, match=message):
        Publisher(endpoint)
    assert check_endpoint("inproc://x") == "inproc://x"


def test_keep_newest_must_be_positive():
    with pytest.raises(ValueError, match="keep_newest"):
        Subscriber("inproc://x", "t", keep_newest=0)


def test_keep_newest_is_per_topic():
    with (
        Publisher("tcp://127.0.0.1:*") as pub,
        Subscriber(pub.endpoint, ["surfaces", "obstacles"], keep_newest=1) as sub,
    ):
        _connected(pub, sub, b"surfaces")
        pub.send([b"surfaces", b"s1"])
        for i in range(5):  # a burst of one topic must not push out the other
            pub.send([b"obstacles", b"o%d" % i])
        time.sleep(0.1)
        got = [sub.recv(0.5), sub.recv(0.5), sub.recv(0.05)]
    assert [bytes(f[1]) for f in got if f] == [b"s1", b"o4"]
    assert sub.dropped == 4


def test_waiting_forever_polls_in_short_slices():
    """recv(None) waits in slices of at most 100 ms: Python runs a signal handler only
    between bytecodes, so a Ctrl-C that lands just before a poll that never ends would be
    handled only when a message comes (a planner on a quiet topic ignored SIGINT that way)."""
    import threading

    waits: list[int] = []

    class Recording:  # the real socket, with its poll timeouts noted
        def __init__(self, sock):
            self._sock = sock

        def poll(self, timeout, flags):
            waits.append(timeout)
            return self._sock.poll(timeout, flags)

        def __getattr__(self, name):
            return getattr(self._sock, name)

    with Publisher("tcp://127.0.0.1:*") as pub, Subscriber(pub.endpoint, "scan") as sub:
        _connected(pub, sub)
        sub.socket = Recording(sub.socket)
        later = threading.Timer(0.5, lambda: pub.send([b"scan", b"late"]))
        later.start()
        frames = sub.recv(None)  # forever, until the message 0.5 s from now
        later.join()
        sub.socket = sub.socket._sock  # closed by the with block
    assert bytes(frames[1]) == b"late"
    assert len(waits) >= 3 and all(0 < w <= 100 for w in waits)
