"""Reading clouds: PCD ``binary_compressed`` (LZF) through supportnode against Open3D.

Times, as medians over ``--repeats`` warm runs: the LZF kernel alone on the file's compressed
block, the plain-Python reference decoder (tests/lzf_reference.py) once, the whole
``read_cloud``, and Open3D's reader when installed (``pip install -e ".[bench]"``). Files: the
640x480 Kinect scans in ../shared/real_scans when present, else a synthetic organised 640x480
scan written by supportnode (literal runs only, so less representative). Prints a table and
one JSON line per file (for bench/ab.py).

    python bench/bench_io.py [--repeats 7] [FILE.pcd ...]
"""

from __future__ import annotations

import argparse
import json
import struct
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from common import median_time, table

from supportnode.io import _lzf
from supportnode.io.clouds import read_cloud, write_pcd

REAL = Path(__file__).resolve().parents[2] / "shared" / "real_scans"
REAL_FILES = ("table_scene_mug_stereo_textured.pcd", "milk_cartoon_all_small_clorox.pcd")


def _compressed_block(path: Path) -> tuple[bytes, int]:
    raw = path.read_bytes()
    marker = b"DATA binary_compressed\n"
    if marker not in raw:
        raise SystemExit(f"bench_io.py: {path}: not a binary_compressed PCD")
    body = raw[raw.index(marker) + len(marker) :]
    csize, usize = struct.unpack("<II", body[:8])
    return body[8 : 8 + csize], usize


def _synthetic(folder: Path) -> Path:
    rng = np.random.default_rng(0)
    u, v = np.meshgrid(np.arange(640), np.arange(480))
    z = 1.0 + 0.3 * rng.random((480, 640))
    pts = np.stack([(u - 320) * z / 525, (v - 240) * z / 525, z], -1).reshape(-1, 3)
    pts[rng.random(len(pts)) < 0.2] = np.nan
    path = folder / "synthetic_640x480.pcd"
    write_pcd(path, pts.astype(np.float32), data="binary_compressed")
    return path


def _open3d_time(path: Path, repeats: int) -> float | None:
    try:
        import open3d as o3d
    except ImportError:
        return None
    return median_time(lambda: o3d.io.read_point_cloud(str(path)), repeats)


def measure(path: Path, repeats: int) -> dict[str, object]:
    import lzf_reference

    block, usize = _compressed_block(path)
    t = time.perf_counter()
    lzf_reference.decompress(block, usize)
    reference = time.perf_counter() - t
    o3d = _open3d_time(path, repeats)
    return {
        "file": path.name,
        "mb": usize / 1e6,
        "lzf_ms": median_time(lambda: _lzf.decompress(block, usize), repeats) * 1e3,
        "reference_lzf_ms": reference * 1e3,
        "read_cloud_ms": median_time(lambda: read_cloud(path), repeats) * 1e3,
        "open3d_ms": None if o3d is None else o3d * 1e3,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="*", type=Path)
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args(argv)
    if args.repeats < 1:
        ap.error(f"--repeats must be at least 1, got {args.repeats}")
    for p in args.files:
        if not p.is_file():
            ap.error(f"{p}: no such file")
    with tempfile.TemporaryDirectory() as tmp:
        files = args.files or [REAL / f for f in REAL_FILES if (REAL / f).exists()]
        files = files or [_synthetic(Path(tmp))]
        rows = [measure(p, args.repeats) for p in files]
    header = list(rows[0])
    print(table([[("-" if r[k] is None else r[k]) for k in header] for r in rows], header))
    for r in rows:
        print(json.dumps(r))
    return 0


if __name__ == "__main__":
    sys.exit(main())
