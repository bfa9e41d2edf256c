"""`supportnode info FILE`: topics, types, counts, duration, rates and sizes of a recording.

Works on everything `supportnode play` plays (our MCAP, ROS MCAP / bags, folders of clouds).
Messages are read once to measure sizes, so damaged files are listed up to the damage (with a
warning line) and converted ROS topics show the size they have on our wire.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import Any


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "source", help="recording (.mcap .bag .db3), ROS 2 bag folder, or folder of clouds"
    )
    parser.add_argument("--topic", default="scan", help="folder of clouds: topic (default scan)")
    parser.add_argument(
        "--hz", type=float, default=10.0, help="folder of clouds: rate (default 10)"
    )


@dataclass
class _Topic:
    type: str
    count: int = 0
    bytes: int = 0
    first: float = 0.0
    last: float = 0.0
    plays: bool = True

    def add(self, time: float, size: int) -> None:
        if self.count == 0:
            self.first = time
        self.count += 1
        self.bytes += size
        self.last = time


def run(args: argparse.Namespace) -> int:
    import sys

    from supportnode.io.sources import McapSource, open_source

    topics: dict[str, _Topic] = {}
    with open_source(args.source, topic=args.topic, hz=args.hz) as src:
        for m in src.messages():
            topics.setdefault(m.topic, _Topic(m.type)).add(m.time, m.size)
        lines = [f"source:    {src.path} ({src.kind}{_size(src.path)})"]
        if isinstance(src, McapSource):
            lines += _mcap_lines(src)
            _foreign_channels(src, topics)
        warnings = list(src.warnings)
    print("\n".join(lines + _message_lines(topics)))
    if topics:
        _topic_table(topics)
    for w in warnings:
        print(f"supportnode info: warning: {w}", file=sys.stderr)
    return 0


def _mcap_lines(src: Any) -> list[str]:
    f, st = src.file, src.file.stats
    state = "indexed" if f.indexed else "not indexed (read linearly)"
    if st.chunk_count:
        ratio = st.uncompressed_bytes / max(1, st.compressed_bytes)
        state += (
            f", {st.chunk_count} chunks, {'/'.join(sorted(st.compression))}, "
            f"compression {ratio:.1f}x"
        )
    lines = [f"mcap:      {state}"]
    meta = f.metadata.get("supportnode")
    if meta:
        lines.append("metadata:  " + ", ".join(f"{k}={v}" for k, v in sorted(meta.items())))
    return lines


def _foreign_channels(src: Any, topics: dict[str, _Topic]) -> None:
    """Channels `play` skips (Foxglove, ROS types other than PointCloud2, ...): counted raw,
    under their schema name and encoding."""
    foreign = {ch.topic: ch for ch in src.file.scan_channels().values() if ch.topic not in topics}
    if not foreign:
        return
    for name, ch in foreign.items():
        schema = ch.schema_name or "no schema"
        topics[name] = _Topic(f"{schema} ({ch.message_encoding or 'no encoding'})", plays=False)
    for raw in src.file.messages(set(foreign)):
        topics[raw.channel.topic].add(raw.log_time * 1e-9, len(raw.data))


def _message_lines(topics: dict[str, _Topic]) -> list[str]:
    import time

    seen = [t for t in topics.values() if t.count]
    if not seen:
        return ["messages:  none"]
    start = min(t.first for t in seen)
    end = max(t.last for t in seen)
    total = sum(t.count for t in seen)
    when = (
        time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(start)) + f" .. {end - start:.3f} s"
        if start > 1e8
        else f"t = {start:.3f} .. {end:.3f} s"
    )
    lines = [f"messages:  {total} over {end - start:.3f} s ({when})"]
    playable = sum(t.count for t in seen if t.plays)
    if playable < total:
        lines.append(
            f"playable:  {playable} (supportnode messages and PointCloud2; "
            "other schemas are listed, not played)"
        )
    return lines


def _topic_table(topics: dict[str, _Topic]) -> None:
    from supportnode.cli._console import print_table

    rows = []
    for name, t in sorted(topics.items()):
        span = t.last - t.first
        rate = f"{(t.count - 1) / span:.2f} Hz" if t.count > 1 and span > 0 else "-"
        avg = _human(t.bytes // t.count) if t.count else "-"
        rows.append((name, t.type, t.count, rate, _human(t.bytes), avg))
    print_table(("topic", "type", "count", "rate", "size", "avg size"), rows, left=2)


def _human(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB"):
        if n < 1000 or unit == "GB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000
    return f"{n:.1f} GB"


def _size(path: str) -> str:
    import os

    if os.path.isfile(path):
        return f", {_human(os.path.getsize(path))}"
    return ""
