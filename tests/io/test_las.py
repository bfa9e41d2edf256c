"""LAS/LAZ input: survey coordinates made local (origin reported), colours and fields, and a
one-line hint when laspy is missing."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import box_points, plane_points

from supportnode.cli import main
from supportnode.errors import CloudFormatError
from supportnode.io.clouds import read_cloud

laspy = pytest.importorskip("laspy")

EAST, NORTH, UP = 512_345.0, 5_402_117.0, 231.0  # UTM-like survey coordinates, metres


def _write_las(path: Path, rng) -> np.ndarray:
    local = np.vstack(
        [
            plane_points(rng, 0, 3, 0, 3, 0.0, 20000),
            plane_points(rng, 1, 2, 1, 1.6, 0.75, 8000),
            box_points(rng, (1.5, 1.3, 0.85), (0.2, 0.2, 0.2), 1500),
        ]
    )
    world = local + [EAST + 0.37, NORTH + 0.61, UP + 0.25]
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales = np.array([0.001, 0.001, 0.001])
    header.offsets = np.array([EAST, NORTH, UP])
    las = laspy.LasData(header)
    las.x, las.y, las.z = world[:, 0], world[:, 1], world[:, 2]
    las.intensity = np.arange(len(world)) % 1000
    las.red = np.full(len(world), 65535)
    las.green = np.zeros(len(world), dtype=np.uint16)
    las.blue = np.full(len(world), 256 * 7)
    las.write(path)
    return world


@pytest.mark.parametrize("ext", ["las", "laz"])
def test_survey_coordinates_are_local_and_exact(tmp_path: Path, rng, ext: str) -> None:
    pytest.importorskip("lazrs") if ext == "laz" else None
    path = tmp_path / f"site.{ext}"
    world = _write_las(path, rng)
    cloud = read_cloud(path)
    np.testing.assert_array_equal(cloud.origin, [EAST, NORTH, UP])
    # millimetre quantisation of the file, nothing lost to the large coordinates
    np.testing.assert_allclose(cloud.points + cloud.origin, world, atol=6e-4, rtol=0)
    assert np.abs(cloud.points).max() < 5.0
    np.testing.assert_array_equal(cloud.fields["rgb"][0], [255, 0, 7])
    assert cloud.fields["intensity"][5] == 5


def test_detect_on_las_reports_the_origin(tmp_path: Path, rng) -> None:
    path = tmp_path / "site.las"
    _write_las(path, rng)
    out = tmp_path / "o"
    assert main(["detect", str(path), "--out", str(out), "--quiet"]) == 0
    result = json.loads((out / "result.json").read_text())
    assert result["input"]["origin"] == [EAST, NORTH, UP]
    heights = sorted(round(s["height"], 2) for s in result["surfaces"])
    assert heights == [0.25, 1.0]  # local: 0.25 m above the origin's height, table 0.75 above
    assert len(result["objects"]) == 1


def test_missing_laspy_is_a_one_line_hint(tmp_path: Path, rng, monkeypatch) -> None:
    path = tmp_path / "site.las"
    _write_las(path, rng)
    monkeypatch.setitem(sys.modules, "laspy", None)
    with pytest.raises(CloudFormatError) as err:
        read_cloud(path)
    assert str(err.value) == (
        f"{path}: reading LAS/LAZ needs laspy: install the LAS extra: "
        "pip install 'supportnode[las]' (laspy and lazrs)"
    )


def test_not_a_las_file(tmp_path: Path) -> None:
    path = tmp_path / "bad.las"
    path.write_bytes(b"LASF" + b"\0" * 50)
    with pytest.raises(CloudFormatError, match=r"bad\.las: not a readable LAS file"):
        read_cloud(path)
