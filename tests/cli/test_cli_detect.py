"""`supportnode detect` end to end: files written, labels aligned with input rows, bad input."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import camera_views
import numpy as np
import pytest
from conftest import box_points, plane_points

from supportnode.cli import main
from supportnode.io.clouds import read_cloud, write_pcd, write_ply


@pytest.fixture
def table_cloud(tmp_path, rng):
    """Floor, a table at 0.75 m, two boxes on the table; written as PLY."""
    pts = np.vstack(
        [
            plane_points(rng, -1.5, 1.5, -1.5, 1.5, 0.0, 40000),
            plane_points(rng, -0.6, 0.6, -0.4, 0.4, 0.75, 15000),
            box_points(rng, (-0.3, 0.0, 0.85), (0.15, 0.15, 0.2), 2000),
            box_points(rng, (0.3, 0.1, 0.80), (0.2, 0.1, 0.1), 2000),
        ]
    )
    path = tmp_path / "room.ply"
    write_ply(path, pts)
    return path, pts


def test_detect_writes_every_output(table_cloud, tmp_path, capsys):
    path, pts = table_cloud
    out = tmp_path / "out"
    assert main(["detect", str(path), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "0.750" in printed and "objects: 2 clusters" in printed
    result = json.loads((out / "result.json").read_text())
    heights = [round(s["height"], 3) for s in result["surfaces"]]
    assert heights == [0.0, 0.75]
    assert set(result["timings"]) >= {"read", "surfaces", "objects", "free_space"}
    assert result["params"]["surfaces"]["method"] == "planar"
    assert len(result["objects"]) == 2
    assert all(o["surface_id"] == 1 for o in result["objects"])
    labels = np.load(out / "labels.npz")
    assert labels["surface"].shape == (len(pts),) and labels["surface"].dtype == np.int32
    assert labels["object"].shape == (len(pts),)
    assert (labels["surface"] == 1).sum() == result["surfaces"][1]["point_count"]
    det = read_cloud(out / "room_detected.ply")
    rest = read_cloud(out / "room_not_detected.ply")
    assert len(det.points) + len(rest.points) == len(pts)
    assert (det.fields["rgb"] == [255, 0, 0]).all() and (rest.fields["rgb"] == [0, 255, 0]).all()
    objs = sorted((out / "room_objects").glob("*.ply"))
    assert [p.name for p in objs] == ["000.ply", "001.ply"]
    sizes = [len(read_cloud(p).points) for p in objs]
    assert sizes == sorted(sizes, reverse=True)
    assert sizes[0] == result["objects"][0]["point_count"]


def test_labels_follow_input_rows_with_nan(tmp_path, rng):
    pts = plane_points(rng, 0, 1, 0, 1, 0.5, 5000)
    pts[::7] = np.nan  # an organised cloud's missing pixels
    path = tmp_path / "org.pcd"
    write_pcd(path, pts, data="binary")
    out = tmp_path / "o"
    assert main(["detect", str(path), "--out", str(out), "--no-objects", "--quiet"]) == 0
    surface = np.load(out / "labels.npz")["surface"]
    assert surface.shape == (5000,)
    assert (surface[::7] == -1).all()
    assert (surface[np.isfinite(pts).all(axis=1)] == 0).mean() > 0.97
    result = json.loads((out / "result.json").read_text())
    assert result["input"]["dropped_nonfinite"] == len(pts[::7])


def test_set_and_config_change_parameters(table_cloud, tmp_path):
    path, _ = table_cloud
    cfg = tmp_path / "c.yaml"
    cfg.write_text("surfaces:\n  method: seed\n")
    out = tmp_path / "o"
    assert (
        main(
            [
                "detect",
                str(path),
                "--config",
                str(cfg),
                "--set",
                "surfaces.psi_min=5",
                "--out",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    params = json.loads((out / "result.json").read_text())["params"]
    assert params["surfaces"]["method"] == "seed" and params["surfaces"]["psi_min"] == 5


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda d: d / "missing.ply", "missing.ply"),
        (lambda d: _write(d / "cloud.foo", "1 2 3\n"), "unknown extension"),
        (lambda d: _write(d / "empty.xyz", ""), "empty.xyz"),
        (lambda d: _write(d / "bad.pcd", "VERSION 0.7\nFIELDS x y z\n"), "bad.pcd"),
    ],
)
def test_bad_input_one_line_exit_2(tmp_path, capsys, make, message):
    path = make(tmp_path)
    assert main(["detect", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1 and "Traceback" not in err


def test_bad_config_key_names_file_and_line(table_cloud, tmp_path, capsys):
    path, _ = table_cloud
    cfg = _write(tmp_path / "typo.yaml", "surfaces:\n  voxl_size: [0.1, 0.1, 0.1]\n")
    assert main(["detect", str(path), "--config", str(cfg)]) == 2
    err = capsys.readouterr().err
    assert "typo.yaml:2" in err and "plane_voxel" in err


def test_console_command_runs_as_a_process(table_cloud, tmp_path):
    path, _ = table_cloud
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "supportnode",
            "detect",
            str(path),
            "--out",
            str(tmp_path / "p"),
            "--set",
            "surfaces.method=sed",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2
    assert "surfaces.method" in proc.stderr and "Traceback" not in proc.stderr


def _write(path, text):
    path.write_text(text)
    return path


def test_align_recovers_heights_of_a_tilted_cloud(tmp_path, rng, capsys):
    """A camera-style cloud, tilted and turned: --align finds the floor and the table 0.75 m
    above it, and says by how much it rotated the cloud."""
    pts = np.vstack(
        [
            plane_points(rng, -1.5, 1.5, -1.5, 1.5, 0.0, 40000),
            plane_points(rng, -0.6, 0.6, -0.4, 0.4, 0.75, 15000),
            box_points(rng, (0.2, 0.0, 0.85), (0.15, 0.15, 0.2), 2000),
            np.c_[rng.uniform(-1.5, 1.5, 6000), np.full(6000, 1.5), rng.uniform(0, 1.5, 6000)],
        ]
    )
    r, p = np.radians([25.0, -30.0])
    rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    path = tmp_path / "tilted.npy"
    np.save(path, pts @ (ry @ rx).T)
    out = tmp_path / "o"
    assert main(["detect", str(path), "--align", "--out", str(out), "--no-objects"]) == 0
    assert "gravity: tilt" in capsys.readouterr().out
    result = json.loads((out / "result.json").read_text())
    heights = [s["height"] for s in result["surfaces"]]
    assert heights[1] - heights[0] == pytest.approx(0.75, abs=0.01)
    assert result["gravity"]["tilt_deg"] == pytest.approx(38.6, abs=1.0)


def test_align_refuses_a_cloud_without_horizontal_surfaces(tmp_path, rng, capsys):
    v = rng.normal(size=(20000, 3))
    np.save(tmp_path / "ball.npy", v / np.linalg.norm(v, axis=1, keepdims=True))
    assert (
        main(["detect", str(tmp_path / "ball.npy"), "--align", "--out", str(tmp_path / "o")]) == 2
    )
    err = capsys.readouterr().err
    assert "horizontal surface" in err and len(err.strip().splitlines()) == 1
    advised = _advice(err, r"--set gravity\.up_hint=\[[-0-9.,]+\]")  # followed: no refusal
    args = ["detect", str(tmp_path / "ball.npy"), "--align", "--out", str(tmp_path / "o")]
    assert main([*args, "--quiet", *advised]) == 0
    assert "no plane family within 60 deg of up_hint" in capsys.readouterr().err


def test_sensor_origin_drops_undersides_and_rejects_bad_values(table_cloud, tmp_path, capsys):
    path, _ = table_cloud
    out = tmp_path / "o"
    args = ["detect", str(path), "--out", str(out), "--no-objects", "--quiet"]
    assert main([*args, "--sensor-origin", "0,0,0.5"]) == 0  # below the table: only the floor
    heights = [s["height"] for s in json.loads((out / "result.json").read_text())["surfaces"]]
    assert heights == [pytest.approx(0.0)]
    # A coordinate list starting with a minus is a value, not an option.
    assert main([*args, "--sensor-origin", "-0.5,0,0.5"]) == 0
    assert len(json.loads((out / "result.json").read_text())["surfaces"]) == 1
    with pytest.raises(SystemExit) as exit_info:
        main([*args, "--sensor-origin", "0,0"])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert "--sensor-origin" in err and "X,Y,Z" in err


def _advice(text: str, pattern: str) -> list[str]:
    """The command-line arguments a message advises (it must advise them)."""
    match = re.search(pattern, text)
    assert match, text
    return match.group(0).split(" ")


def test_align_puts_the_sensor_at_the_camera(tmp_path, capsys):
    """A camera-frame cloud: --align takes the camera at the frame's origin, so the shelf board
    it sees from below is no surface (main reported it 0.4 m above the camera);
    --sensor-origin still overrides."""
    cloud, _ = camera_views.room_with_shelf(5)
    path = tmp_path / "cam.npy"
    np.save(path, cloud)
    out = tmp_path / "o"
    args = ["detect", str(path), "--align", "--out", str(out), "--no-objects", "--quiet"]
    assert main(args) == 0
    surfaces = json.loads((out / "result.json").read_text())["surfaces"]
    large = [s["height"] for s in surfaces if s["area"] > 0.3]  # not the far wall's noise
    assert large == [pytest.approx(-1.4, abs=0.02), pytest.approx(-0.65, abs=0.02)]
    assert max(s["height"] for s in surfaces) < 0.0
    # Told the sensor was 3 m above the camera: the board is below it, a surface again.
    assert main([*args, "--sensor-origin", "0,-3,0"]) == 0
    heights = [s["height"] for s in json.loads((out / "result.json").read_text())["surfaces"]]
    assert pytest.approx(0.4, abs=0.02) in heights


def test_millimetre_cloud_is_flagged_and_units_mm_finds_the_table(table_cloud, tmp_path, capsys):
    _, pts = table_cloud
    path = tmp_path / "mm.ply"
    write_ply(path, pts * 1000.0)
    out = tmp_path / "o"
    assert main(["detect", str(path), "--out", str(out), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "looks like mm" in err and "no surface found" in err
    assert json.loads((out / "result.json").read_text())["surfaces"] == []
    advised = _advice(err, r"--units mm")
    assert main(["detect", str(path), "--out", str(out), "--quiet", *advised]) == 0
    result = json.loads((out / "result.json").read_text())
    assert [round(s["height"], 3) for s in result["surfaces"]] == [0.0, 0.75]
    assert result["units"] == {"file": "mm", "metres_per_unit": 0.001}
    assert capsys.readouterr().err == ""


def test_no_surface_says_what_to_check_and_the_advice_works(tmp_path, capsys):
    cloud, _ = camera_views.tabletop(6, 45.0)
    path = tmp_path / "table.npy"
    np.save(path, cloud)
    out = tmp_path / "o"
    assert main(["detect", str(path), "--out", str(out), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "no surface found" in err and "units" in err and len(err.strip().splitlines()) == 1
    advised = _advice(err, r"--align")
    assert main(["detect", str(path), "--out", str(out), "--quiet", *advised]) == 0
    surfaces = json.loads((out / "result.json").read_text())["surfaces"]
    assert surfaces[0]["height"] == pytest.approx(-0.6, abs=0.01)
    assert capsys.readouterr().err == ""


def test_bare_wall_refusal_advises_a_hint_that_works(tmp_path, capsys):
    cloud, _ = camera_views.wall(7)
    path = tmp_path / "wall.npy"
    np.save(path, cloud)
    args = ["detect", str(path), "--align", "--out", str(tmp_path / "o"), "--quiet"]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "only one bare plane" in err and len(err.strip().splitlines()) == 1
    advised = _advice(err, r"--set gravity\.up_hint=\[[-0-9.,]+\]")
    assert main([*args, *advised]) == 0
    assert capsys.readouterr().err == ""
