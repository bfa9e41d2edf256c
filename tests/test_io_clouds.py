"""Tests for supportnode.io.clouds: every format round-trips, bad files raise CloudFormatError."""

from __future__ import annotations

import re
import struct
from pathlib import Path

import lzf_reference
import numpy as np
import plyfile
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from supportnode.errors import CloudFormatError
from supportnode.io import _lzf
from supportnode.io.clouds import Cloud, read_cloud, write_cloud, write_pcd, write_ply

DATA = Path(__file__).parent / "data"
REAL = Path(__file__).resolve().parents[2] / "shared" / "real_scans"


def _cloud(n: int = 50, seed: int = 0) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(n, 3))
    colors = rng.integers(0, 256, size=(n, 3), dtype=np.uint8)
    fields = {
        "intensity": rng.random(n).astype(np.float32),
        "role": rng.integers(-5, 5, n).astype(np.int32),
        "object": rng.integers(0, 100, n).astype(np.int32),
        "surface": rng.integers(-1, 3, n).astype(np.int32),
        "primitive": rng.integers(0, 7, n).astype(np.int32),
        "ring": rng.integers(0, 64, n).astype(np.uint16),
    }
    return pts, colors, fields


def _assert_fields_equal(got: dict[str, np.ndarray], want: dict[str, np.ndarray]) -> None:
    assert set(got) == set(want)
    for key, arr in want.items():
        assert got[key].dtype == arr.dtype, key
        np.testing.assert_array_equal(got[key], arr, err_msg=key)


# ------------------------------------------------------------------------------------------ PLY


@pytest.mark.parametrize("binary", [True, False])
def test_ply_round_trip_keeps_values_and_dtypes(tmp_path: Path, binary: bool) -> None:
    pts, colors, fields = _cloud()
    path = tmp_path / "sim.ply"
    write_ply(path, pts, colors=colors, fields=fields, binary=binary)
    cloud = read_cloud(path)
    assert isinstance(cloud, Cloud)
    assert cloud.points.dtype == np.float64 and cloud.points.shape == (50, 3)
    np.testing.assert_array_equal(cloud.points, pts)
    _assert_fields_equal(cloud.fields, {**fields, "rgb": colors})
    np.testing.assert_array_equal(cloud.source_index, np.arange(50))
    assert (cloud.input_count, cloud.dropped_nonfinite, cloud.width) == (50, 0, None)
    assert cloud.path == str(path)


@pytest.mark.parametrize("byte_order", ["<", ">"])
def test_ply_written_by_plyfile_both_endiannesses_with_faces(
    tmp_path: Path, byte_order: str
) -> None:
    vert = np.array(
        [
            (0.0, 0.0, 0.5, 10, 20, 30, 7),
            (1.0, 0.0, 0.5, 40, 50, 60, 8),
            (0.0, 1.0, 0.5, 1, 2, 3, 9),
        ],
        dtype=[
            ("x", "f4"),
            ("y", "f4"),
            ("z", "f4"),
            ("red", "u1"),
            ("green", "u1"),
            ("blue", "u1"),
            ("label", "i4"),
        ],
    )
    faces = np.array([([0, 1, 2],), ([2, 1, 0, 1],)], dtype=[("vertex_indices", "O")])
    ply = plyfile.PlyData(
        [plyfile.PlyElement.describe(vert, "vertex"), plyfile.PlyElement.describe(faces, "face")],
        byte_order=byte_order,
    )
    path = tmp_path / "mesh.PLY"
    ply.write(str(path))
    assert (b"binary_big_endian" in path.read_bytes()[:200]) == (byte_order == ">")
    cloud = read_cloud(path)
    np.testing.assert_array_equal(cloud.points, [[0, 0, 0.5], [1, 0, 0.5], [0, 1, 0.5]])
    np.testing.assert_array_equal(cloud.fields["rgb"], [[10, 20, 30], [40, 50, 60], [1, 2, 3]])
    assert cloud.fields["label"].dtype == np.int32
    np.testing.assert_array_equal(cloud.fields["label"], [7, 8, 9])


def test_ply_ascii_by_hand_with_rgb_short_names_and_nan(tmp_path: Path) -> None:
    path = tmp_path / "hand.ply"
    path.write_text(
        "ply\nformat ascii 1.0\ncomment by hand\nelement vertex 3\n"
        "property double x\nproperty double y\nproperty double z\n"
        "property uchar r\nproperty uchar g\nproperty uchar b\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "0.1 0.2 0.3 255 0 0\nnan 0 0 0 255 0\n1e3 -2 3.5 0 0 255\n3 0 1 2\n"
    )
    cloud = read_cloud(path)
    np.testing.assert_array_equal(cloud.points, [[0.1, 0.2, 0.3], [1000, -2, 3.5]])
    np.testing.assert_array_equal(cloud.fields["rgb"], [[255, 0, 0], [0, 0, 255]])
    np.testing.assert_array_equal(cloud.source_index, [0, 2])
    assert (cloud.input_count, cloud.dropped_nonfinite) == (3, 1)


def test_ply_int64_field_narrowed_and_nk_field_split(tmp_path: Path) -> None:
    pts = np.zeros((4, 3))
    fields = {"ids": np.arange(4, dtype=np.int64), "normal": np.eye(4, 3, dtype=np.float32)}
    write_ply(tmp_path / "a.ply", pts, fields=fields)
    cloud = read_cloud(tmp_path / "a.ply")
    assert cloud.fields["ids"].dtype == np.int32
    np.testing.assert_array_equal(cloud.fields["normal_1"], [0, 1, 0, 0])
    with pytest.raises(CloudFormatError, match=r"b\.ply: field 'big'"):
        write_ply(tmp_path / "b.ply", pts, fields={"big": np.full(4, 2**40, dtype=np.int64)})


# ------------------------------------------------------------------------------------------ PCD


@pytest.mark.parametrize("data", ["ascii", "binary", "binary_compressed"])
def test_pcd_round_trip_keeps_values_and_dtypes(tmp_path: Path, data: str) -> None:
    pts, colors, fields = _cloud(seed=1)
    rng = np.random.default_rng(2)
    fields = {
        **fields,
        "rgb": colors,
        "normal": rng.normal(size=(50, 3)).astype(np.float32),
        "stamp": rng.integers(0, 2**62, 50, dtype=np.uint64),
        "flag": rng.integers(-128, 127, 50, dtype=np.int8),
        "weight": rng.normal(size=50),
    }
    path = tmp_path / "c.pcd"
    write_pcd(path, pts, fields=fields, data=data)
    assert f"DATA {data}\n".encode() in path.read_bytes()
    cloud = read_cloud(path)
    np.testing.assert_array_equal(cloud.points, pts)
    if data == "ascii":  # ascii integers go through float64: exact only below 2**53
        fields["stamp"] = fields["stamp"] >> np.uint64(12)
        write_pcd(path, pts, fields=fields, data=data)
        cloud = read_cloud(path)
    _assert_fields_equal(cloud.fields, fields)
    assert cloud.viewpoint is not None and cloud.viewpoint.shape == (7,)


def test_pcd_float32_points_written_as_f4(tmp_path: Path) -> None:
    pts = np.random.default_rng(3).normal(size=(10, 3)).astype(np.float32)
    write_cloud(tmp_path / "f.pcd", pts, colors=np.full((10, 3), 7, np.uint8))
    assert b"SIZE 4 4 4 4\nTYPE F F F F\n" in (tmp_path / "f.pcd").read_bytes()
    cloud = read_cloud(tmp_path / "f.pcd")
    np.testing.assert_array_equal(cloud.points, pts.astype(np.float64))
    np.testing.assert_array_equal(cloud.fields["rgb"], np.full((10, 3), 7))


def _organised_pcd_bytes(data_kind: str = "binary") -> tuple[bytes, np.ndarray]:
    """A 4x3 organised cloud with NaN pixels, a padding field and a packed float rgb."""
    xyz = np.arange(36, dtype=np.float32).reshape(12, 3)
    xyz[[1, 5, 6, 11]] = np.nan
    xyz[7, 2] = np.inf
    rgb = (np.arange(12, dtype=np.uint32) * 0x010203) | np.uint32(0xFF000000)
    header = (
        "# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z _ rgb ring\n"
        "SIZE 4 4 4 1 4 2\nTYPE F F F U F U\nCOUNT 1 1 1 3 1 1\nWIDTH 4\nHEIGHT 3\n"
        f"VIEWPOINT 1 2 3 1 0 0 0\nPOINTS 12\nDATA {data_kind}\n"
    )
    rec = np.zeros(
        12, dtype=[("xyz", "<f4", (3,)), ("pad", "u1", (3,)), ("rgb", "<u4"), ("ring", "<u2")]
    )
    rec["xyz"], rec["rgb"], rec["ring"] = xyz, rgb, np.arange(12)
    return header.encode() + rec.tobytes(), xyz


def test_organised_pcd_with_nans_padding_and_packed_rgb(tmp_path: Path) -> None:
    raw, xyz = _organised_pcd_bytes()
    path = tmp_path / "org.pcd"
    path.write_bytes(raw)
    cloud = read_cloud(path)
    keep = np.array([0, 2, 3, 4, 8, 9, 10])
    np.testing.assert_array_equal(cloud.source_index, keep)
    assert cloud.source_index.dtype == np.int64
    assert (cloud.input_count, cloud.dropped_nonfinite) == (12, 5)
    assert (cloud.width, cloud.height) == (4, 3)
    np.testing.assert_array_equal(cloud.viewpoint, [1, 2, 3, 1, 0, 0, 0])
    np.testing.assert_array_equal(cloud.points, xyz[keep].astype(np.float64))
    assert set(cloud.fields) == {"rgb", "ring"}
    np.testing.assert_array_equal(cloud.fields["ring"], keep)
    want_rgb = np.stack([keep * 1, keep * 2, keep * 3], axis=1)
    np.testing.assert_array_equal(cloud.fields["rgb"], want_rgb)


def test_pcd_v06_ascii_and_rgb_in_both_ascii_spellings(tmp_path: Path) -> None:
    packed = np.array([0x00102030, 0x00FF0001], dtype=np.uint32)
    as_float = packed.view(np.float32)
    path = tmp_path / "v06.pcd"
    path.write_text(
        "VERSION .6\nFIELDS x y z rgb\nSIZE 4 4 4 4\nTYPE F F F F\nWIDTH 2\nHEIGHT 1\nPOINTS 2\n"
        f"DATA ascii\n1 2 3 {packed[0]}\n4 5 6 {float(as_float[1])!r}\n"
    )
    cloud = read_cloud(path)
    np.testing.assert_array_equal(cloud.points, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(cloud.fields["rgb"], [[0x10, 0x20, 0x30], [0xFF, 0, 1]])
    assert cloud.width is None and cloud.viewpoint is None


def test_pcd_float_rgb_that_is_not_a_colour_is_kept_as_float(tmp_path: Path) -> None:
    # SICK Visionary-T files store intensity as ordinary floats in the "rgb" field
    write_pcd(tmp_path / "t.pcd", np.zeros((3, 3)), fields={"rgb_src": np.float32([0.1, 0.2, 0.5])})
    raw = (tmp_path / "t.pcd").read_bytes().replace(b"rgb_src", b"rgb")
    (tmp_path / "t.pcd").write_bytes(raw)
    cloud = read_cloud(tmp_path / "t.pcd")
    np.testing.assert_array_equal(cloud.fields["rgb_float"], np.float32([0.1, 0.2, 0.5]))


def test_binary_compressed_fixture_from_another_tool() -> None:
    # tests/data/mug_crop_lzf.pcd: a crop of a real PCL scan, compressed by python-lzf (liblzf),
    # so it holds genuine back-references, unlike our literal-only writer
    cloud = read_cloud(DATA / "mug_crop_lzf.pcd")
    assert (cloud.width, cloud.height, cloud.input_count) == (40, 30, 1200)
    assert len(cloud) == 800 and cloud.dropped_nonfinite == 400
    assert cloud.source_index[0] == 400
    np.testing.assert_allclose(
        cloud.points.sum(axis=0), [-268.8291701376438, -341.8800502717495, 1617.3601011037827]
    )
    np.testing.assert_allclose(cloud.points[0], [-0.37607, -0.44625, 2.017], rtol=1e-6)
    np.testing.assert_array_equal(cloud.fields["rgb"][0], [0x44, 0x44, 0x42])


def test_lzf_kernel_matches_reference_on_fixture_and_handles_overlaps() -> None:
    raw = (DATA / "mug_crop_lzf.pcd").read_bytes()
    body = raw[raw.index(b"DATA binary_compressed\n") + 23 :]
    csize, usize = struct.unpack("<II", body[:8])
    out = _lzf.decompress(body[8 : 8 + csize], usize)
    assert out.dtype == np.uint8 and out.size == usize == 1200 * 16
    assert out.tobytes() == lzf_reference.decompress(body[8 : 8 + csize], usize)
    assert np.isnan(np.frombuffer(out, "<f4", 400)).all()  # first 10 image rows are empty
    # "ab" literal, then a back-reference of 7 bytes at distance 2 (overlapping), then "c"
    stream = bytes([1]) + b"ab" + bytes([(5 << 5) | 0, 1]) + bytes([0]) + b"c"
    assert _lzf.decompress(stream, 10).tobytes() == b"ababababac"
    # length 7 + extension byte 2: 11 bytes of one repeated byte at distance 1
    stream = bytes([0]) + b"z" + bytes([(7 << 5) | 0, 2, 0])
    assert _lzf.decompress(stream, 12).tobytes() == b"z" * 12
    bad_streams = [
        (stream[:-1], 12, "ends inside a token"),
        (stream, 11, "back-reference outside"),
        (bytes([(1 << 5), 5]), 3, "back-reference outside"),
        (b"\x05ab", 6, "literal run past the end"),
        (b"\x01ab", 3, "expands to 2 bytes, header says 3"),
    ]
    for bad, size, message in bad_streams:
        with pytest.raises(_lzf.LZFError, match=message):
            _lzf.decompress(bad, size)
        with pytest.raises(ValueError):
            lzf_reference.decompress(bad, size)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.binary(min_size=1, max_size=40), min_size=1, max_size=30), st.data())
def test_lzf_kernel_decodes_back_references_like_the_reference(chunks, data) -> None:
    # repeated chunks give the greedy compressor back-references of every length and distance
    picks = data.draw(st.lists(st.integers(0, len(chunks) - 1), max_size=200))
    payload = b"".join(chunks[i] for i in picks) + bytes(data.draw(st.integers(0, 300)))
    stream = lzf_reference.compress(payload)
    assert lzf_reference.decompress(stream, len(payload)) == payload
    assert _lzf.decompress(stream, len(payload)).tobytes() == payload


@pytest.mark.parametrize("size", [0, 1, 31, 32, 33, 1000])
def test_literal_lzf_round_trip(size: int) -> None:
    data = bytes(np.random.default_rng(size).integers(0, 256, size, dtype=np.uint8))
    stream = _lzf.compress_literal(data)
    assert _lzf.decompress(stream, size).tobytes() == lzf_reference.decompress(stream, size) == data


@pytest.mark.real
def test_real_binary_compressed_kinect_frame() -> None:
    path = REAL / "table_scene_mug_stereo_textured.pcd"
    if not path.exists():
        pytest.skip(f"{path} not present")
    cloud = read_cloud(path)  # its speed is bench/bench_io.py's business, not a test's
    assert (cloud.width, cloud.height, cloud.input_count) == (640, 480, 307200)
    assert 200_000 < len(cloud) < 220_000
    assert len(cloud) + cloud.dropped_nonfinite == 307200
    assert cloud.fields["rgb"].shape == (len(cloud), 3)
    assert 0.3 < float(np.median(cloud.points[:, 2])) < 3.0  # metres in front of the camera


# -------------------------------------------------------------------------- text, numpy, OBJ


def test_xyz_whitespace_with_comments_and_extra_columns(tmp_path: Path) -> None:
    path = tmp_path / "scan.xyz"
    path.write_text("# exported\n1 2 3 0.5 7\n\n4\t5 6 0.25 8  # trailing\nnan 1 1 0 0\n")
    cloud = read_cloud(path)
    np.testing.assert_array_equal(cloud.points, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(cloud.fields["col3"], [0.5, 0.25])
    np.testing.assert_array_equal(cloud.fields["col4"], [7, 8])
    assert cloud.dropped_nonfinite == 1


def test_csv_with_header_names_and_colour(tmp_path: Path) -> None:
    path = tmp_path / "scan.CSV"
    path.write_text("intensity,X,Y,Z,r,g,b\n0.5,1,2,3,255,0,10\n0.7,4,5,6,0,128,0\n")
    cloud = read_cloud(path)
    np.testing.assert_array_equal(cloud.points, [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(cloud.fields["intensity"], [0.5, 0.7])
    np.testing.assert_array_equal(cloud.fields["rgb"], [[255, 0, 10], [0, 128, 0]])


def test_txt_three_columns(tmp_path: Path) -> None:
    (tmp_path / "p.txt").write_text("1.5 2 3\n")
    np.testing.assert_array_equal(read_cloud(tmp_path / "p.txt").points, [[1.5, 2, 3]])


def test_npy_plain_wide_and_structured(tmp_path: Path) -> None:
    pts = np.random.default_rng(4).normal(size=(20, 3))
    write_cloud(tmp_path / "a.npy", pts)
    np.testing.assert_array_equal(read_cloud(tmp_path / "a.npy").points, pts)
    np.save(tmp_path / "b.npy", np.column_stack([pts, np.arange(20)]))
    np.testing.assert_array_equal(read_cloud(tmp_path / "b.npy").fields["col3"], np.arange(20))
    _, colors, fields = _cloud(20)
    write_cloud(tmp_path / "c.npy", pts, colors=colors, fields=fields)
    cloud = read_cloud(tmp_path / "c.npy")
    np.testing.assert_array_equal(cloud.points, pts)
    _assert_fields_equal(cloud.fields, {**fields, "rgb": colors})


def test_npz_round_trip_and_alternative_keys(tmp_path: Path) -> None:
    pts, colors, fields = _cloud(30)
    fields["normal"] = np.ones((30, 3), np.float32)
    write_cloud(tmp_path / "a.npz", pts, colors=colors, fields=fields)
    cloud = read_cloud(tmp_path / "a.npz")
    np.testing.assert_array_equal(cloud.points, pts)
    _assert_fields_equal(cloud.fields, {**fields, "rgb": colors})
    np.savez(tmp_path / "b.npz", x=pts[:, 0], y=pts[:, 1], z=pts[:, 2], pose=np.eye(4))
    cloud = read_cloud(tmp_path / "b.npz")
    np.testing.assert_array_equal(cloud.points, pts)
    assert cloud.fields == {}
    np.savez(tmp_path / "c.npz", xyz=pts.astype(np.float32))
    np.testing.assert_array_equal(read_cloud(tmp_path / "c.npz").points, pts.astype(np.float32))


def test_obj_vertices_with_colour_faces_ignored(tmp_path: Path) -> None:
    path = tmp_path / "m.obj"
    path.write_text(
        "# obj\nmtllib x.mtl\nv 0 0 0 1 0 0\nv 1 0 0 0 1 0\nvn 0 0 1\nvt 0.5 0.5\n"
        "v 0 1 0 0 0 0.5\nf 1 2 3\n"
    )
    cloud = read_cloud(path)
    np.testing.assert_array_equal(cloud.points, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    np.testing.assert_array_equal(cloud.fields["rgb"], [[255, 0, 0], [0, 255, 0], [0, 0, 128]])


# -------------------------------------------------------------------------------- properties

_finite = st.floats(-1e6, 1e6, allow_nan=False, width=64)


@settings(
    max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    pts=hnp.arrays(np.float64, st.tuples(st.integers(1, 40), st.just(3)), elements=_finite),
    ext=st.sampled_from(["ply", "pcd-binary", "pcd-binary_compressed", "pcd-ascii", "npz"]),
    seed=st.integers(0, 2**16),
)
def test_random_arrays_round_trip(tmp_path: Path, pts: np.ndarray, ext: str, seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = pts.shape[0]
    fields = {"label": rng.integers(-(2**31), 2**31 - 1, n).astype(np.int32), "w": rng.random(n)}
    path = tmp_path / f"r.{ext[:3]}"
    if ext.startswith("pcd"):
        write_pcd(path, pts, fields=fields, data=ext[4:])
    else:
        write_cloud(path, pts, fields=fields)
    cloud = read_cloud(path)
    np.testing.assert_array_equal(cloud.points, pts)
    _assert_fields_equal(cloud.fields, fields)


# ------------------------------------------------------------------------------------ errors


def _pcd_header(**over: str) -> str:
    keys = {
        "VERSION": "0.7",
        "FIELDS": "x y z",
        "SIZE": "4 4 4",
        "TYPE": "F F F",
        "COUNT": "1 1 1",
        "WIDTH": "2",
        "HEIGHT": "1",
        "POINTS": "2",
        "DATA": "ascii",
    }
    keys.update(over)
    return "".join(f"{k} {v}\n" for k, v in keys.items() if v != "-")


def _bad_files(tmp: Path) -> list[tuple[Path, str]]:
    """(file, expected message fragment) for every kind of bad input."""
    cases: list[tuple[Path, str]] = []

    def add(fname: str, content: bytes | str, match: str) -> None:
        p = tmp / fname
        p.write_bytes(content.encode() if isinstance(content, str) else content)
        cases.append((p, match))

    cases.append((tmp / "missing.ply", "no such file"))
    (tmp / "adir.pcd").mkdir()
    cases.append((tmp / "adir.pcd", "directory"))
    add("x.foo", "1 2 3\n", "unknown extension '.foo'")
    good, _ = _organised_pcd_bytes()
    add("trunc.pcd", good[:-10], r"truncated binary data: expected 252 bytes, found 242")
    write_pcd(tmp / "tc.pcd", np.ones((100, 3)), data="binary_compressed")
    add("trunc_c.pcd", (tmp / "tc.pcd").read_bytes()[:-50], "truncated binary_compressed")
    add(
        "corrupt_c.pcd",
        (tmp / "tc.pcd").read_bytes()[:-50] + bytes([0xE0]) * 50,
        "binary_compressed",
    )
    add("nofields.pcd", _pcd_header(FIELDS="-") + "1 2 3\n", "no FIELDS")
    add(
        "width.pcd",
        _pcd_header(WIDTH="abc") + "1 2 3\n",
        "header line 6: WIDTH must be an integer, got 'abc'",
    )
    add("datakind.pcd", _pcd_header(DATA="zip"), "unknown DATA kind 'zip'")
    add(
        "sizes.pcd",
        _pcd_header(SIZE="4 4") + "1 2 3\n",
        "header line 3: FIELDS and SIZE counts differ",
    )
    add("noxyz.pcd", _pcd_header(FIELDS="a b c") + "1 2 3\n", "no x, y, z")
    add("nodata.pcd", _pcd_header(DATA="-"), "no DATA line")
    add("garbage.pcd", b"\x89PNG\r\n\x1a\n\x00\x00", "not a PCD file")
    add("asciibad.pcd", _pcd_header() + "1 2 3\n4 five 6\n", "line 11: cannot parse 'five'")
    add("asciishort.pcd", _pcd_header() + "1 2 3\n", "truncated ascii data")
    add(
        "allnan.pcd",
        _pcd_header() + "nan 1 1\n1 inf 1\n",
        r"no finite points \(2 rows, all NaN/Inf\)",
    )
    add("empty.pcd", _pcd_header(WIDTH="0", POINTS="0"), "no points")
    ply_head = "ply\nformat binary_little_endian 1.0\nelement vertex 3\n"
    ply_props = "property float x\nproperty float y\nproperty float z\nend_header\n"
    add(
        "trunc.ply",
        (ply_head + ply_props).encode() + b"\x00" * 20,
        "truncated binary data: expected 36 bytes of vertices, found 20",
    )
    add(
        "novertex.ply",
        "ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int v\nend_header\n",
        "no vertex element",
    )
    add(
        "noz.ply",
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n1 2\n",
        "no z property",
    )
    add("header.ply", "ply\nformat weird 1.0\nend_header\n", "header.ply")
    add("notply.ply", "hello\n", "notply.ply")
    add("zero.ply", "ply\nformat ascii 1.0\nelement vertex 0\n" + ply_props, "no points")
    add(
        "badnum.ply",
        "ply\nformat ascii 1.0\nelement vertex 1\n" + ply_props + "1 x 3\n",
        "badnum.ply",
    )
    add("bad.xyz", "1 2 3\n4 5 6\n7 8 oops\n", "line 3: cannot parse 'oops'")
    add("ragged.csv", "1,2,3\n4,5\n", "line 2: expected 3 values, found 2")
    add("two.txt", "1 2\n3 4\n", "at least 3 columns")
    add("blank.xyz", "# nothing here\n\n", "no points")
    add("binary.xyz", b"\xff\xfe\x00garbage\x81", "not a text file")
    add("bad.obj", "v 1 2 3\nv 4 5 x\n", "line 2: cannot parse 'x'")
    add("empty.obj", "f 1 2 3\n", "no points")
    add("bad.npy", b"not numpy at all", "not a .npy file")
    np.save(tmp / "objects.npy", np.array([{"a": 1}]), allow_pickle=True)
    cases.append((tmp / "objects.npy", "Python objects"))
    np.save(tmp / "full.npy", np.zeros((4, 3)))
    add("trunc.npy", (tmp / "full.npy").read_bytes()[:-8], "trunc.npy")
    np.save(tmp / "shape.npy", np.zeros((4, 2)))
    cases.append((tmp / "shape.npy", r"expected an \(N, 3\)"))
    np.savez(tmp / "keys.npz", pts=np.zeros((4, 3)))
    cases.append((tmp / "keys.npz", "no 'points'"))
    add("bad.npz", b"PK\x03\x04 broken zip", "bad.npz")
    return cases


def test_every_bad_input_raises_one_line_cloud_format_error(tmp_path: Path) -> None:
    problems = []
    for path, match in _bad_files(tmp_path):
        try:
            read_cloud(path)
        except CloudFormatError as err:
            msg = str(err)
            if not (re.search(match, msg) and msg.startswith(f"{path}:") and "\n" not in msg):
                problems.append(f"{path.name}: {msg!r} !~ {match!r}")
        except Exception as err:
            problems.append(f"{path.name}: raw {type(err).__name__}: {err}")
        else:
            problems.append(f"{path.name}: no error")
    assert not problems, "\n".join(problems)


def test_write_errors_name_the_file(tmp_path: Path) -> None:
    with pytest.raises(CloudFormatError, match=r"out\.pcd: unknown PCD data kind"):
        write_pcd(tmp_path / "out.pcd", np.zeros((2, 3)), data="zip")
    with pytest.raises(CloudFormatError, match=r"out\.xyz: unknown extension"):
        write_cloud(tmp_path / "out.xyz", np.zeros((2, 3)))
    with pytest.raises(CloudFormatError, match=r"out\.ply: points must be an \(N, 3\)"):
        write_ply(tmp_path / "out.ply", np.zeros((2, 2)))
    with pytest.raises(CloudFormatError, match=r"out\.ply: field 'a' must have 2 rows"):
        write_ply(tmp_path / "out.ply", np.zeros((2, 3)), fields={"a": np.zeros(3)})
    with pytest.raises(CloudFormatError, match=r"nodir.*out\.npz: cannot write"):
        write_cloud(tmp_path / "nodir" / "out.npz", np.zeros((2, 3)))


def test_ply_general_path_vertex_after_other_element_and_list_property(tmp_path: Path) -> None:
    # written by hand: plyfile 1.1.5 writes rows holding a list property in native byte
    # order even under a big-endian header
    header = (
        "ply\nformat binary_big_endian 1.0\nelement camera 1\nproperty float view_px\n"
        "element vertex 2\nproperty double x\nproperty double y\nproperty double z\n"
        "property list uchar short feat\nend_header\n"
    )
    body = struct.pack(">f", 1.0)
    body += struct.pack(">dddBhh", 1, 3, 5, 2, 1, 2) + struct.pack(">dddBhh", 2, 4, 6, 2, 3, 4)
    (tmp_path / "g.ply").write_bytes(header.encode() + body)
    cloud = read_cloud(tmp_path / "g.ply")
    np.testing.assert_array_equal(cloud.points, [[1, 3, 5], [2, 4, 6]])
    np.testing.assert_array_equal(cloud.fields["feat"], [[1, 2], [3, 4]])
    raw = (tmp_path / "g.ply").read_bytes()
    (tmp_path / "gt.ply").write_bytes(raw[:-6])
    with pytest.raises(CloudFormatError, match=r"gt\.ply: truncated data"):
        read_cloud(tmp_path / "gt.ply")
