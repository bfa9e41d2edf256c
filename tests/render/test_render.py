"""`supportnode render` and supportnode.render: picture size, what is drawn where, errors."""

from __future__ import annotations

import json
import sys

import numpy as np
import pytest
from conftest import box_points, plane_points

from supportnode.cli import main
from supportnode.errors import SupportNodeError
from supportnode.io.clouds import write_ply

pytest.importorskip("matplotlib")

from matplotlib.image import imread

from supportnode.render import (
    draw_frame,
    load_result_dir,
    project,
    render_frame,
    render_result,
)
from supportnode.render.draw import OTHER_RGB, OUTLINE_RGB, SURFACE_RGB

TABLE = (-0.6, 0.6, -0.4, 0.4, 0.75)  # x0, x1, y0, y1, z
BOX_CENTER, BOX_SIZE = (0.3, 0.05, 0.85), (0.15, 0.15, 0.2)  # too small to be a surface


@pytest.fixture(scope="module")
def detected(tmp_path_factory):
    """Floor, table, one box on the table: written as PLY and run through `supportnode detect`.
    Returns (result folder, result dict)."""
    rng = np.random.default_rng(7)
    x0, x1, y0, y1, z = TABLE
    pts = np.vstack(
        [
            plane_points(rng, -1.5, 1.5, -1.5, 1.5, 0.0, 30000),
            plane_points(rng, x0, x1, y0, y1, z, 12000),
            box_points(rng, BOX_CENTER, BOX_SIZE, 4000),
        ]
    )
    root = tmp_path_factory.mktemp("render")
    cloud = root / "scene.ply"
    write_ply(cloud, pts)
    out = root / "scene"
    assert main(["detect", str(cloud), "--out", str(out), "--quiet"]) == 0
    result = json.loads((out / "result.json").read_text())
    assert [round(s["height"], 2) for s in result["surfaces"]] == [0.0, 0.75]  # the premise
    assert len(result["objects"]) == 1 and result["objects"][0]["surface_id"] == 1
    return out, result


def _pixel(ax, height_px: int, world: tuple[float, float, float], view: str = "top"):
    """(row, col) in the saved image of a world point (display origin is bottom left)."""
    x, y = ax.transData.transform(project(np.array(world), view))[0]
    return round(height_px - y), round(x)


def _window(img: np.ndarray, rc: tuple[int, int], r: int) -> np.ndarray:
    row, col = rc
    return img[row - r : row + r + 1, col - r : col + r + 1, :3].reshape(-1, 3)


def _near(pixels: np.ndarray, rgb, tol: float = 0.12) -> np.ndarray:
    return np.abs(pixels - np.asarray(rgb)).max(axis=1) < tol


def _mostly(pixels: np.ndarray, rgb) -> bool:
    """Most of the non-white pixels have this colour (points leave white gaps between them)."""
    inked = pixels[pixels.min(axis=1) < 0.9]
    return len(inked) > 0 and _near(inked, rgb).mean() > 0.8


def _far_from_drawn_lines(result: dict, xy: tuple[float, float], margin: float) -> bool:
    """The test points must not sit under an outline, a box edge or a disc circle."""
    p = np.asarray(xy)
    for f in result["free_space"]:
        if abs(np.hypot(*(p - f["disc_center"])) - f["disc_radius"]) < margin:
            return False
    for s in result["surfaces"]:
        for ring in s["outline"]:
            r = np.asarray(ring)
            for a, b in zip(r, np.roll(r, -1, axis=0), strict=True):
                t = np.clip(np.dot(p - a, b - a) / max(np.dot(b - a, b - a), 1e-12), 0, 1)
                if np.hypot(*(a + t * (b - a) - p)) < margin:
                    return False
    return True


def test_top_view_draws_surfaces_objects_outline_and_legend(detected, tmp_path):
    out, result = detected
    size, dpi = (1000, 800), 100
    fig, ax = draw_frame(load_result_dir(out), view="top", color="class", size=size, dpi=dpi)
    png = tmp_path / "top.png"
    fig.savefig(png, dpi=dpi)
    img = imread(png)
    assert img.shape[:2] == (size[1], size[0])

    # a table point (the table covers the floor under it in the top view): surface red; inside
    # the table's free disc, clear of the circle, so the spot holds table points and nothing else
    disc = next(f for f in result["free_space"] if f["surface_id"] == 1)
    assert disc["disc_radius"] > 0.15
    table_pt = (disc["disc_center"][0] + 0.05, disc["disc_center"][1] + 0.05, TABLE[4])
    assert _far_from_drawn_lines(result, table_pt[:2], 0.05)
    assert _mostly(_window(img, _pixel(ax, size[1], table_pt), 3), SURFACE_RGB)
    # the box's top, off its edges: object points are "the rest", green
    box_pt = (BOX_CENTER[0] + 0.03, BOX_CENTER[1] - 0.03, BOX_CENTER[2] + BOX_SIZE[2] / 2)
    assert _mostly(_window(img, _pixel(ax, size[1], box_pt), 2), OTHER_RGB)
    # the table's outline: the outline colour along the middle of its longest edge
    ring = np.asarray(result["surfaces"][1]["outline"][0])
    edges = np.roll(ring, -1, axis=0) - ring
    k = int(np.argmax(np.hypot(edges[:, 0], edges[:, 1])))
    mid = ring[k] + edges[k] / 2
    window = _window(img, _pixel(ax, size[1], (mid[0], mid[1], TABLE[4])), 2)
    assert _near(window, OUTLINE_RGB, 0.2).any()
    # every surface and object is labelled; the legend is there and drawn above the axes
    texts = [t.get_text() for t in ax.texts]
    assert {"S0  0.00 m", "S1  0.75 m", "#0"} <= set(texts)
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert legend[0].startswith("surface points") and "largest free disc" in legend
    top_band = img[: int(size[1] * 0.08), :, :3].reshape(-1, 3)
    assert _near(top_band, SURFACE_RGB).sum() > 20  # the legend's red marker


def test_render_result_writes_png_of_exact_size(detected, tmp_path):
    out, _ = detected
    for size, dpi in (((640, 480), 80), ((1200, 900), 100)):
        png = render_result(out, tmp_path / f"r{size[0]}.png", size=size, dpi=dpi)
        assert imread(png).shape == (size[1], size[0], 4)


@pytest.mark.parametrize("view", ["side", "oblique"])
def test_side_and_oblique_views(detected, tmp_path, view):
    out, _ = detected
    png = tmp_path / f"{view}.png"
    assert (
        main(["render", str(out), "--view", view, "-o", str(png), "--size", "640x480", "--quiet"])
        == 0
    )
    img = imread(png)
    assert img.shape == (480, 640, 4)
    assert (img[..., :3].min(axis=2) < 0.9).mean() > 0.02  # something is drawn


def test_side_view_puts_the_table_at_its_height(detected, tmp_path):
    out, _ = detected
    size = (800, 600)
    fig, ax = draw_frame(load_result_dir(out), view="side", size=size)
    png = tmp_path / "side.png"
    fig.savefig(png, dpi=100)
    img = imread(png)
    # side view: picture x is world x, picture y is world z (y is depth)
    assert np.allclose(project(np.array([-0.4, 9.0, 0.75]), "side"), [[-0.4, 0.75]])
    ink = _window(img, _pixel(ax, size[1], (-0.4, 0.0, TABLE[4]), "side"), 2)
    assert (ink.min(axis=1) < 0.8).any()  # the table seen edge-on
    above = _window(img, _pixel(ax, size[1], (-0.4, 0.0, 1.3), "side"), 2)
    assert (above.min(axis=1) > 0.85).all()  # nothing above the box tops


def test_color_by_id_and_subsampling(detected, tmp_path):
    out, result = detected
    frame = load_result_dir(out)
    n = len(frame.points)
    assert (
        frame.object is not None
        and (frame.object == 0).sum() == result["objects"][0]["point_count"]
    )
    fig, ax = draw_frame(frame, color="id", max_points=1000, size=(640, 480))
    drawn = ax.collections[0].get_offsets()
    assert len(drawn) == 1000
    legend = " ".join(t.get_text() for t in fig.legends[0].get_texts())
    n_surface = int((frame.surface >= 0).sum())
    assert f"({n_surface:,})" in legend and "colour by id" in legend  # counts: all points
    assert n > 1000
    # the subset is seeded: the same picture twice
    _, ax2 = draw_frame(frame, color="id", max_points=1000, size=(640, 480))
    assert np.array_equal(drawn, ax2.collections[0].get_offsets())


def test_points_from_input_cloud_when_plys_are_gone(detected, tmp_path):
    out, _ = detected
    copy = tmp_path / "copy"
    copy.mkdir()
    for name in ("result.json", "labels.npz"):
        (copy / name).write_bytes((out / name).read_bytes())
    with_plys = load_result_dir(out)
    frame = load_result_dir(copy)  # the input path in result.json is absolute here
    assert len(frame.points) == len(with_plys.points)
    assert (frame.surface >= 0).sum() == (with_plys.surface >= 0).sum()
    assert (frame.object >= 0).sum() == (with_plys.object >= 0).sum()
    png = render_frame(frame, tmp_path / "x.png", color="id", size=(400, 300))
    assert imread(png).shape == (300, 400, 4)


def test_missing_matplotlib_gives_clear_error(detected, tmp_path, monkeypatch, capsys):
    out, _ = detected
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # `import matplotlib` now fails
    with pytest.raises(SupportNodeError, match=r"render needs matplotlib: pip install"):
        render_result(out, tmp_path / "x.png")
    assert main(["render", str(out), "-o", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pip install 'supportnode[viz]'" in err
    assert not (tmp_path / "x.png").exists()


def test_missing_folder_and_corrupt_result_exit_2_with_one_line(tmp_path, capsys):
    assert main(["render", str(tmp_path / "nope")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "nope: no such folder" in err

    bad = tmp_path / "bad"
    bad.mkdir()
    assert main(["render", str(bad)]) == 2
    assert "result.json: no such file" in capsys.readouterr().err
    (bad / "result.json").write_text('{"surfaces": [')
    assert main(["render", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not valid JSON" in err
    (bad / "result.json").write_text('{"surfaces": [{"id": 0}]}')
    assert main(["render", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "malformed result" in err


def test_bad_options(detected, tmp_path, capsys):
    out, _ = detected
    with pytest.raises(SystemExit):
        main(["render", str(out), "--size", "12"])
    assert "WxH" in capsys.readouterr().err
    assert main(["render", str(out), "-o", str(tmp_path / "x.jpg")]) == 2
    assert "PNG" in capsys.readouterr().err


def test_detect_render_flag_writes_result_png(tmp_path, rng):
    pts = np.vstack(
        [
            plane_points(rng, -1, 1, -1, 1, 0.0, 8000),
            box_points(rng, (0.0, 0.0, 0.1), (0.15, 0.15, 0.2), 1500),
        ]
    )
    cloud = tmp_path / "small.ply"
    write_ply(cloud, pts)
    out = tmp_path / "o"
    assert main(["detect", str(cloud), "--out", str(out), "--render", "--quiet"]) == 0
    assert imread(out / "result.png").shape == (1200, 1600, 4)


def test_far_outliers_are_drawn_at_the_edge_not_fitted(detected):
    import dataclasses

    out, _ = detected
    frame = load_result_dir(out)
    n = len(frame.points)
    far = np.tile([[40.0, 35.0, 0.5]], (n // 100, 1))  # 1 % of returns 50 m away
    frame = dataclasses.replace(frame, points=np.vstack([frame.points, far]),
                                surface=np.r_[frame.surface, np.full(len(far), -1, np.int32)],
                                object=None)  # fmt: skip
    _, ax = draw_frame(frame, size=(800, 600))
    (x0, x1), (_, y1) = ax.get_xlim(), ax.get_ylim()
    assert x1 < 3.0 and y1 < 3.0 and x0 > -3.0  # the 3 x 3 m floor fills the picture
    drawn = ax.collections[0].get_offsets()
    assert np.isclose(drawn[:, 0], x1).sum() >= len(far) * 0.9  # outliers on the edge


def test_color_id_on_an_organised_cloud_with_nan_rows(tmp_path, rng):
    from supportnode.io.clouds import write_pcd

    x0, x1, y0, y1, z = TABLE
    pts = np.vstack(
        [
            plane_points(rng, -1.5, 1.5, -1.5, 1.5, 0.0, 20000),
            plane_points(rng, x0, x1, y0, y1, z, 8000),
            box_points(rng, BOX_CENTER, BOX_SIZE, 3000),
        ]
    )
    pts[::9] = np.nan  # a depth camera's missing pixels
    cloud = tmp_path / "org.pcd"
    write_pcd(cloud, pts, data="binary")
    out = tmp_path / "o"
    assert main(["detect", str(cloud), "--out", str(out), "--quiet"]) == 0
    frame = load_result_dir(out)
    result = json.loads((out / "result.json").read_text())
    assert frame.notes == []
    assert frame.object is not None
    assert (frame.object == 0).sum() == result["objects"][0]["point_count"]


def test_render_draws_the_cloud_when_nothing_was_found(tmp_path, rng):
    cloud = tmp_path / "noise.ply"
    write_ply(cloud, rng.uniform(0, 1, (3000, 3)))
    out = tmp_path / "o"
    assert main(["detect", str(cloud), "--out", str(out), "--render", "--quiet"]) == 0
    assert json.loads((out / "result.json").read_text())["surfaces"] == []
    frame = load_result_dir(out)
    assert len(frame.points) == 3000
    img = imread(out / "result.png")
    assert img.shape[:2] == (1200, 1600)
