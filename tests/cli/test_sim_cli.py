"""`supportnode sim` through supportnode.cli.main: files written, their contents, exit codes."""

from __future__ import annotations

import json

import numpy as np
import pytest

import supportnode.cli as cli
from supportnode.io.clouds import read_cloud
from supportnode.sim.files import read_sim_npz


@pytest.fixture(autouse=True)
def only_sim(monkeypatch):
    # The parser imports every subcommand module; keep this test independent of the others.
    monkeypatch.setattr(cli, "COMMANDS", {"sim": cli.COMMANDS["sim"]})


def test_sampled_ply_with_ground_truth(tmp_path, capsys):
    out = tmp_path / "shelf.ply"
    assert cli.main(["sim", "shelf", "--points", "20000", "--out", str(out)]) == 0
    assert capsys.readouterr().out.strip() == f"{out} (20000 points)"
    cloud = read_cloud(out)
    assert cloud.points.shape == (20000, 3)
    assert {"role", "primitive", "object", "surface"} <= set(cloud.fields)
    assert cloud.fields["surface"].dtype == np.int32 and cloud.fields["surface"].max() == 4
    top = cloud.points[cloud.fields["surface"] == 1]  # board_1, top at 0.40 m
    assert np.allclose(top[:, 2], 0.40, atol=1e-5)


def test_lidar_frames_to_directory(tmp_path, capsys):
    out = tmp_path / "scans"
    argv = ["sim", "table_chairs", "--sensor", "lidar", "--preset", "vlp16", "--frames", "2"]
    argv += ["--noise", "range:0.01", "--noise", "outliers:0.01", "--seed", "3"]
    assert cli.main([*argv, "--out", str(out)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 3 and lines[-1] == str(out / "trajectory.json")
    traj = json.loads((out / "trajectory.json").read_text())
    assert traj["scene"] == "table_chairs" and traj["seed"] == 3 and traj["rate_hz"] == 10.0
    assert [f["file"] for f in traj["frames"]] == ["frame_000.npz", "frame_001.npz"]
    f1 = read_sim_npz(out / "frame_001.npz")
    assert f1.stamp == pytest.approx(0.1) and f1.frame == "world"
    assert np.allclose(f1.sensor_pose, traj["frames"][1]["sensor_pose"])
    assert (f1.role == 3).any() and len(f1) == traj["frames"][1]["points"]
    with np.load(out / "frame_000.npz") as z:
        assert {"points", "role", "primitive", "object", "surface", "sensor_pose", "stamp"} <= set(
            z
        )
        assert z["points"].dtype == np.float32 and z["sensor_pose"].shape == (4, 4)


def test_several_frames_to_numbered_files_sensor_frame(tmp_path):
    out = tmp_path / "k.npz"
    argv = ["sim", "u_table", "--sensor", "camera", "--frames", "2", "--frame", "sensor"]
    assert cli.main([*argv, "--noise", "tilt:2,1", "--out", str(out)]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "k_000.npz",
        "k_001.npz",
        "k_trajectory.json",
    ]
    c = read_sim_npz(tmp_path / "k_001.npz")
    assert c.frame == "sensor" and not np.allclose(c.tilt_rotation, np.eye(3))
    world = c.to_frame("world")
    untilted = world.points @ world.tilt_rotation  # back to z up
    surf = untilted[world.surface == 1]  # the U table top at 0.75 m
    assert len(surf) > 100 and np.allclose(surf[:, 2], 0.75, atol=1e-3)


def test_scene_from_a_path(tmp_path):
    scene = tmp_path / "tiny.yaml"
    scene.write_text("primitives:\n  - {kind: box, size: [1, 1, 1], role: surface, surface: s}\n")
    assert cli.main(["sim", str(scene), "--points", "100", "--out", str(tmp_path / "t.npz")]) == 0
    assert len(read_sim_npz(tmp_path / "t.npz")) == 100


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["nope"], "unknown scene 'nope'"),
        (["BAD"], "bad.yaml:2: primitive 0: unknown kind 'cilinder'"),
        (["shelf", "--noise", "fog:1"], "noise 'fog:1'"),
        (["shelf", "--noise", "range:0.01"], "range noise follows sensor rays"),
        (["shelf", "--sensor", "lidar", "--preset", "d435"], "camera preset"),
        (["shelf", "--points", "0"], "--points must be at least 1"),
        (["shelf", "--noise", "kinect"], "kinect noise, --organized and --frame optical need"),
        (["shelf", "--sensor", "lidar", "--organized"], "need --sensor camera"),
        (["shelf", "--noise", "kinect:x"], "'x' is not a number"),
    ],
)
def test_bad_input_exits_2_with_one_line(tmp_path, capsys, args, message):
    bad = tmp_path / "bad.yaml"
    bad.write_text("primitives:\n  - {kind: cilinder, radius: 1, height: 1, role: structure}\n")
    args = [str(bad) if a == "BAD" else a for a in args]
    assert cli.main(["sim", *args, "--out", str(tmp_path / "x.ply")]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not (tmp_path / "x.ply").exists()


def test_organised_kinect_scan_in_the_optical_frame(tmp_path):
    out = tmp_path / "k.npz"
    argv = ["sim", "u_table", "--sensor", "camera", "--preset", "kinect", "--noise", "kinect"]
    assert cli.main([*argv, "--organized", "--frame", "optical", "--out", str(out)]) == 0
    cloud = read_sim_npz(out)
    assert cloud.image_shape == (480, 640) and len(cloud) == 480 * 640
    seen = np.isfinite(cloud.points[:, 0])
    assert 0.1 < seen.mean() < 1.0 and (cloud.points[seen, 2] > 0.4).all()  # z forward
    assert (cloud.role[~seen] == -1).all()


def test_sim_writes_a_recording_that_play_reads(tmp_path):
    from supportnode.io.sources import open_source

    out = tmp_path / "seq.mcap"
    args = ["sim", "table_chairs", "--sensor", "lidar", "--preset", "vlp16", "--frames", "3"]
    assert cli.main([*args, "--out", str(out)]) == 0
    with open_source(out) as src:
        msgs = [m.decode() for m in src.messages()]
    assert [m.seq for m in msgs] == [0, 1, 2]
    assert [round(m.stamp, 3) for m in msgs] == [0.0, 0.1, 0.2]
    assert all(m.pose is not None and m.count > 1000 for m in msgs)
