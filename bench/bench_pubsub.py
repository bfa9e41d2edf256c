"""Publish/subscribe cost of a 131,072-point scan (x, y, z, intensity float32: 2 MB) on
127.0.0.1: our wire (encode, bus, decode) beside plain pyzmq sending the same raw bytes and
beside a plain in-memory copy of them.

    python bench/bench_pubsub.py [--points 131072] [--messages 200] [--hz 50] [--seconds 2]

Latency: ``--messages`` messages at ``--hz``, publisher -> subscriber (a thread of this process),
send stamp to the moment the subscriber holds the decoded message; median and p99. Max rate:
publish as fast as possible for ``--seconds`` while the subscriber receives (and decodes) as fast
as it can; messages received per second (the publisher's queue drops what it cannot hand on,
so "sent" may be higher). The copy row is ``np.copy`` of the 2 MB buffer (rate = 1 / mean time).
Target: our wire within 2x of plain pyzmq.
"""

from __future__ import annotations

import argparse
import statistics
import struct
import threading
import time
from collections.abc import Callable

import numpy as np
import zmq

from supportnode.client import Publisher, Subscriber
from supportnode.msgs import PointCloud

TOPIC = "scan"


class Transport:
    """One way of moving a scan: ``send(stamp)`` and ``recv(timeout) -> stamp | None``."""

    name = ""

    def send(self, stamp: float) -> None:
        raise NotImplementedError

    def recv(self, timeout: float) -> float | None:
        raise NotImplementedError

    def close(self) -> None:
        raise NotImplementedError


class Ours(Transport):
    """`supportnode.client` Publisher / Subscriber: encode (validates), bus, decode."""

    name = "supportnode (encode/bus/decode)"

    def __init__(self, cloud: PointCloud) -> None:
        self.cloud = cloud
        self.pub = Publisher("tcp://127.0.0.1:*", TOPIC, hwm=10)
        # keep_newest=4: a subscriber that keeps up never drops on its side.
        self.sub = Subscriber(TOPIC, self.pub.endpoint, keep_newest=4)

    def send(self, stamp: float) -> None:
        self.cloud.stamp = stamp
        self.cloud.seq += 1
        self.pub.publish(self.cloud)

    def recv(self, timeout: float) -> float | None:
        msg = self.sub.recv(timeout)
        return None if msg is None else msg.stamp

    def close(self) -> None:
        self.sub.close()
        self.pub.close()


class PlainZmq(Transport):
    """pyzmq PUB/SUB multipart ``[topic, stamp (8 bytes), raw 2 MB]``, zero-copy both ways."""

    name = "plain pyzmq multipart"

    def __init__(self, raw: bytes) -> None:
        ctx = zmq.Context.instance()
        self.raw = raw
        self.pub = ctx.socket(zmq.PUB)
        self.pub.setsockopt(zmq.LINGER, 0)
        self.pub.setsockopt(zmq.SNDHWM, 10)
        self.pub.bind("tcp://127.0.0.1:*")
        self.sub = ctx.socket(zmq.SUB)
        self.sub.setsockopt(zmq.LINGER, 0)
        self.sub.setsockopt(zmq.RCVHWM, 8)
        self.sub.setsockopt(zmq.SUBSCRIBE, TOPIC.encode())
        self.sub.connect(self.pub.getsockopt_string(zmq.LAST_ENDPOINT))

    def send(self, stamp: float) -> None:
        self.pub.send_multipart([TOPIC.encode(), struct.pack("<d", stamp), self.raw], copy=False)

    def recv(self, timeout: float) -> float | None:
        if not self.sub.poll(max(1, int(timeout * 1000)), zmq.POLLIN):
            return None
        parts = self.sub.recv_multipart(copy=False)
        return struct.unpack("<d", parts[1].buffer)[0]

    def close(self) -> None:
        self.sub.close(linger=0)
        self.pub.close(linger=0)


class Receiver(threading.Thread):
    """Receives until stopped, recording send-to-receive latencies and a count."""

    def __init__(self, transport: Transport) -> None:
        super().__init__(daemon=True)
        self.transport = transport
        self.latencies: list[float] = []
        self.stop = threading.Event()

    def run(self) -> None:
        while not self.stop.is_set():
            stamp = self.transport.recv(0.1)
            if stamp is not None:
                self.latencies.append(time.time() - stamp)


def measure(transport: Transport, messages: int, hz: float, seconds: float) -> dict[str, float]:
    """Latency median/p99 at ``hz`` and the maximum received rate of one transport."""
    rx = Receiver(transport)
    rx.start()
    try:
        # Slow joiner: send until the subscription has arrived and a message came through.
        deadline = time.monotonic() + 5.0
        while not rx.latencies:
            if time.monotonic() > deadline:
                raise RuntimeError(f"{transport.name}: nothing received")
            transport.send(time.time())
            time.sleep(0.05)
        time.sleep(0.2)

        rx.latencies.clear()
        start = time.monotonic()
        for i in range(messages):
            time.sleep(max(0.0, start + i / hz - time.monotonic()))
            transport.send(time.time())
        time.sleep(0.3)
        lat = np.asarray(rx.latencies)
        received_paced = len(lat)

        rx.latencies.clear()
        sent = 0
        start = time.monotonic()
        while time.monotonic() - start < seconds:
            transport.send(time.time())
            sent += 1
        elapsed = time.monotonic() - start
        received = len(rx.latencies)  # what arrived within the window
        time.sleep(0.3)
    finally:
        rx.stop.set()
        rx.join()
    return {
        "median_ms": float(np.median(lat)) * 1e3,
        "p99_ms": float(np.percentile(lat, 99)) * 1e3,
        "received_paced": received_paced,
        "sent_hz": sent / elapsed,
        "max_hz": received / elapsed,
    }


def measure_copy(raw: bytes, messages: int) -> dict[str, float]:
    """np.copy of the raw buffer (through a memoryview), ``messages`` times."""
    view = np.frombuffer(memoryview(raw), dtype=np.uint8)
    times = []
    for _ in range(messages):
        t = time.perf_counter()
        np.copy(view)
        times.append(time.perf_counter() - t)
    return {
        "median_ms": statistics.median(times) * 1e3,
        "p99_ms": float(np.percentile(times, 99)) * 1e3,
        "received_paced": messages,
        "sent_hz": float("nan"),
        "max_hz": 1.0 / statistics.fmean(times),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=131_072)
    parser.add_argument("--messages", type=int, default=200)
    parser.add_argument("--hz", type=float, default=50.0)
    parser.add_argument("--seconds", type=float, default=2.0)
    args = parser.parse_args()

    rng = np.random.default_rng(0)
    xyz = rng.uniform(-10, 10, (args.points, 3)).astype(np.float32)
    intensity = rng.uniform(0, 1, args.points).astype(np.float32)
    cloud = PointCloud.from_xyz(xyz, stamp=0.0, frame_id="lidar", fields={"intensity": intensity})
    raw = np.ascontiguousarray(np.c_[xyz, intensity]).tobytes()
    wire = sum(memoryview(f).nbytes for f in cloud.encode(TOPIC))
    print(
        f"{args.points} points x,y,z,intensity float32: raw {len(raw) / 1e6:.2f} MB, "
        f"our message {wire / 1e6:.2f} MB; {args.messages} messages at {args.hz:g} Hz, "
        f"then {args.seconds:g} s flat out; 127.0.0.1"
    )

    rows: list[tuple[str, dict[str, float]]] = []
    factories: list[tuple[str, Callable[[], Transport]]] = [
        (Ours.name, lambda: Ours(cloud)),
        (PlainZmq.name, lambda: PlainZmq(raw)),
    ]
    for name, make in factories:
        transport = make()
        try:
            rows.append((name, measure(transport, args.messages, args.hz, args.seconds)))
        finally:
            transport.close()
    rows.append(("np.copy of the bytes (memoryview)", measure_copy(raw, args.messages)))

    print()
    print(
        f"{'':36} {'median ms':>10} {'p99 ms':>8} {'recv@' + format(args.hz, 'g') + 'Hz':>10} "
        f"{'sent/s':>8} {'max recv/s':>10}"
    )
    for name, r in rows:
        sent = "-" if np.isnan(r["sent_hz"]) else f"{r['sent_hz']:.0f}"
        print(
            f"{name:36} {r['median_ms']:10.3f} {r['p99_ms']:8.3f} "
            f"{r['received_paced']:>10.0f} {sent:>8} {r['max_hz']:10.0f}"
        )
    ours, plain = rows[0][1], rows[1][1]
    print()
    print(
        f"ours / plain pyzmq: median latency {ours['median_ms'] / plain['median_ms']:.2f}x, "
        f"p99 {ours['p99_ms'] / plain['p99_ms']:.2f}x, "
        f"max rate {plain['max_hz'] / max(ours['max_hz'], 1e-9):.2f}x slower (target: within 2x)"
    )


if __name__ == "__main__":
    main()
