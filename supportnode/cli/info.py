"""`supportnode info FILE`: topics, types, counts, duration, rates and sizes of a recording.

Works on everything `supportnode play` plays (our MCAP, ROS MCAP / bags, folders of clouds).
Messages are read once to measure sizes, so damaged files are listed up to the damage (with a
warning line) and converted ROS topics show the size they have on our wire.
"""

from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "source", help="recording (.mcap .bag .db3), ROS 2 bag folder, or folder of clouds"
    )
    parser.add_argument("--topic", default="scan", help="folder of clouds: topic (default scan)")
    parser.add_argument(
        "--hz", type=float, default=10.0, help="folder of clouds: rate (default 10)"
    )


def run(args: argparse.Namespace) -> int:
    import sys
    import time
    from dataclasses import dataclass

    from supportnode.io.sources import McapSource, open_source

    @dataclass
    class Topic:
        type: str
        count: int = 0
        bytes: int = 0
        first: float = 0.0
        last: float = 0.0

    topics: dict[str, Topic] = {}
    with open_source(args.source, topic=args.topic, hz=args.hz) as src:
        for m in src.messages():
            t = topics.get(m.topic)
            if t is None:
                t = topics[m.topic] = Topic(m.type, first=m.time)
            t.count += 1
            t.bytes += m.size
            t.last = m.time
        lines = [f"source:    {src.path} ({src.kind}{_size(src.path)})"]
        if isinstance(src, McapSource):
            f, st = src.file, src.file.stats
            state = "indexed" if f.indexed else "not indexed (read linearly)"
            if st.chunk_count:
                ratio = st.uncompressed_bytes / max(1, st.compressed_bytes)
                state += (
                    f", {st.chunk_count} chunks, {'/'.join(sorted(st.compression))}, "
                    f"compression {ratio:.1f}x"
                )
            lines.append(f"mcap:      {state}")
            meta = f.metadata.get("supportnode")
            if meta:
                lines.append("metadata:  " + ", ".join(f"{k}={v}" for k, v in sorted(meta.items())))
        warnings = list(src.warnings)
    if topics:
        start = min(t.first for t in topics.values())
        end = max(t.last for t in topics.values())
        total = sum(t.count for t in topics.values())
        when = (
            time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(start)) + f" .. {end - start:.3f} s"
            if start > 1e8
            else f"t = {start:.3f} .. {end:.3f} s"
        )
        lines.append(f"messages:  {total} over {end - start:.3f} s ({when})")
        width = max(5, *(len(n) for n in topics))
        lines.append(
            f"{'topic':<{width}}  {'type':<16} {'count':>7} {'rate':>10} {'size':>10} {'avg size':>10}"
        )
        for name, t in sorted(topics.items()):
            span = t.last - t.first
            rate = f"{(t.count - 1) / span:.2f} Hz" if t.count > 1 and span > 0 else "-"
            lines.append(
                f"{name:<{width}}  {t.type:<16} {t.count:>7} {rate:>10} {_human(t.bytes):>10} "
                f"{_human(t.bytes // t.count):>10}"
            )
    else:
        lines.append("messages:  none playable")
    print("\n".join(lines))
    for w in warnings:
        print(f"supportnode info: warning: {w}", file=sys.stderr)
    return 0


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
