"""The Rerun view: `detect --save x.rrd` and `view --rerun --save` write scenes whose entities
read back with Rerun's own reader (cloud, surfaces, objects, what holds what)."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import box_points, plane_points

from supportnode.cli import main
from supportnode.io.clouds import write_ply

rr_chunk = pytest.importorskip("rerun.chunk")

REPO = Path(__file__).resolve().parents[2]


def entities(path: Path) -> dict[str, dict[str, list]]:
    """entity path -> component column -> values (all rows of all chunks)."""
    out: dict[str, dict[str, list]] = {}
    for chunk in rr_chunk.RrdReader(path).stream():
        batch = chunk.to_record_batch()
        cols = out.setdefault(chunk.entity_path, {})
        for name in batch.schema.names:
            if name in ("rerun.controls.RowId", "log_time", "stamp"):
                continue  # the index columns: times, not content
            cols.setdefault(name, []).extend(batch.column(name).to_pylist())
    return out


def test_detect_saves_cloud_surfaces_objects_and_support(tmp_path: Path, rng) -> None:
    pts = np.vstack(
        [
            plane_points(rng, -1.5, 1.5, -1.5, 1.5, 0.0, 30000),
            plane_points(rng, -0.6, 0.6, -0.4, 0.4, 0.75, 12000),
            box_points(rng, (0.3, 0.05, 0.85), (0.15, 0.15, 0.2), 3000),
        ]
    )
    cloud = tmp_path / "room.ply"
    write_ply(cloud, pts)
    rrd = tmp_path / "room.rrd"
    res = subprocess.run(
        [sys.executable, "-m", "supportnode", "detect", str(cloud), "--out", str(tmp_path / "o"),
         "--save", str(rrd)],
        capture_output=True, text=True, cwd=REPO, timeout=120,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert f"wrote {rrd}" in res.stdout
    ent = entities(rrd)
    (positions,) = ent["/world/scan"]["Points3D:positions"]
    assert len(positions) == len(pts)
    floor, table = ent["/world/surfaces/0"], ent["/world/surfaces/1"]
    assert floor["height"] == [[0.0]] or floor["height"][0][0] == pytest.approx(0.0, abs=0.01)
    assert table["height"][0][0] == pytest.approx(0.75, abs=0.01)
    assert table["LineStrips3D:labels"][0][0].startswith("S1 0.75 m")
    strip = np.asarray(table["LineStrips3D:strips"][0][0])
    assert np.allclose(strip[:, 2], table["height"][0][0])  # the outline at its height
    (box,) = ent["/world/objects/0"]["Boxes3D:labels"]
    assert box == ["#0"]
    assert ent["/world/support/0"]["Arrows3D:labels"] == [["#0 on S1"]]


def test_view_rerun_saves_the_live_node(tmp_path: Path) -> None:
    from supportnode.client import Publisher, SupportSurfaces
    from supportnode.msgs import SupportSurface

    rrd = tmp_path / "live.rrd"
    with Publisher("tcp://127.0.0.1:*", "surfaces") as pub:
        proc = subprocess.Popen(
            [sys.executable, "-m", "supportnode", "view", "--save", str(rrd), "--endpoint",
             pub.endpoint, "--no-scan", "--duration", "4"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=REPO,
        )  # fmt: skip
        square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
        deadline = time.monotonic() + 3.5
        seq = 0
        while time.monotonic() < deadline:
            seq += 1
            s = SupportSurface(id=7, height=0.5, normal=np.array([0, 0, 1.0]), area=1.0,
                               outline=[square], safe=True)  # fmt: skip
            pub.publish(SupportSurfaces(time.time(), "map", seq, [s]))
            time.sleep(0.1)
        out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert "messages written to" in out
    ent = entities(rrd)
    assert ent["/world/surfaces/7"]["LineStrips3D:labels"][0][0].startswith("S7 0.50 m")


def test_missing_rerun_is_one_line(tmp_path: Path, rng, monkeypatch, capsys) -> None:
    cloud = tmp_path / "p.ply"
    write_ply(cloud, plane_points(rng, 0, 1, 0, 1, 0.5, 3000))
    monkeypatch.setitem(sys.modules, "rerun", None)
    args = ["detect", str(cloud), "--out", str(tmp_path / "o"), "--save", str(tmp_path / "x.rrd")]
    assert main([*args, "--quiet"]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "supportnode detect: error: the Rerun view needs rerun-sdk: install the Rerun extra: "
        "pip install 'supportnode[rerun]'"
    ]
