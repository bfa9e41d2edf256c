"""`detect` on sequences (recordings, folders of frames or clouds): per-scan results in one
MCAP and a JSON line each, --every / --start / --duration, progress, Ctrl-C."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from conftest import plane_points
from hypothesis import given, settings
from hypothesis import strategies as st

from supportnode.cli import _console, main
from supportnode.io.clouds import write_ply
from supportnode.io.recording import McapFile
from supportnode.io.scans import ScanSelection
from supportnode.msgs import decode_any

REPO = Path(__file__).resolve().parents[2]
FRAMES = REPO / "sim_scans" / "shelf_lidar"  # 5 posed frames at 10 Hz
RECORDING = REPO / "sim_scans" / "shelf_lidar.mcap"


def _lines(out: Path) -> list[dict]:
    return [json.loads(x) for x in (out / "results.jsonl").read_text().splitlines()]


def _mcap_messages(path: Path) -> list:
    with McapFile(path) as f:
        return [decode_any(m.frames()) for m in f.messages()]


def test_frames_folder_every_second_scan_in_the_map_frame(tmp_path: Path, capsys) -> None:
    out = tmp_path / "o"
    assert main(["detect", str(FRAMES), "--every", "2", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "3 scans on topic 'scan'" in printed and "results.jsonl" in printed
    lines = _lines(out)
    assert [x["seq"] for x in lines] == [0, 2, 4]
    assert [x["stamp"] for x in lines] == pytest.approx([0.0, 0.2, 0.4])
    for x in lines:
        assert x["frame_id"] == "map"
        heights = sorted(s["height"] for s in x["surfaces"])
        # poses applied: the floor is at 0 m and the shelf boards at 0.4 and 0.8 m
        assert heights[0] == pytest.approx(0.0, abs=0.02)
        assert any(abs(h - 0.4) < 0.02 for h in heights)
        assert x["obstacles"]
    msgs = _mcap_messages(out / "results.mcap")
    kinds = [type(m).__name__ for m in msgs]
    assert kinds.count("SupportSurfaces") == 3 and kinds.count("ObstacleClusters") == 3
    first = next(m for m in msgs if type(m).__name__ == "SupportSurfaces")
    assert [s.id for s in first.surfaces] == [s["id"] for s in lines[0]["surfaces"]]


def test_recording_window_start_and_duration(tmp_path: Path) -> None:
    out = tmp_path / "o"
    args = ["detect", str(RECORDING), "--start", "0.15", "--duration", "0.2", "--quiet"]
    assert main([*args, "--out", str(out)]) == 0
    assert [x["stamp"] for x in _lines(out)] == pytest.approx([0.2, 0.3])


def test_folder_of_cloud_files(tmp_path: Path, rng) -> None:
    folder = tmp_path / "clouds"
    folder.mkdir()
    for i, z in enumerate((0.5, 0.7)):
        write_ply(folder / f"c_{i}.ply", plane_points(rng, 0, 1, 0, 1, z, 4000))
    out = tmp_path / "o"
    assert main(["detect", str(folder), "--out", str(out), "--quiet", "--no-objects"]) == 0
    lines = _lines(out)
    assert [round(x["surfaces"][0]["height"], 2) for x in lines] == [0.5, 0.7]
    assert all("obstacles" not in x for x in lines)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--topic", "lidar"], "no PointCloud topic 'lidar' (there are: scan)"),
        (["--render"], "--render, --view, --save and --sensor-origin are for one cloud"),
        (["--every", "0"], None),
    ],
)
def test_bad_sequence_options_are_one_line(tmp_path: Path, capsys, extra, message) -> None:
    try:
        code = main(["detect", str(RECORDING), "--out", str(tmp_path / "o"), *extra])
    except SystemExit as exc:  # argparse
        code = exc.code
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    if message is not None:
        assert len(err) == 1 and message in err[0]


def test_ctrl_c_names_the_partial_results(tmp_path: Path, capsys, monkeypatch) -> None:
    real = ScanSelection.scans

    def two_then_ctrl_c(self, source, topic):
        for i, scan in enumerate(real(self, source, topic)):
            if i == 2:
                raise KeyboardInterrupt
            yield scan

    monkeypatch.setattr(ScanSelection, "scans", two_then_ctrl_c)
    out = tmp_path / "o"
    assert main(["detect", str(FRAMES), "--out", str(out)]) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        f"supportnode detect: interrupted after 2 scans; their results are in "
        f"{out / 'results.mcap'} and {out / 'results.jsonl'}"
    ]
    assert len(_lines(out)) == 2
    assert len(_mcap_messages(out / "results.mcap")) == 4  # finished file, both topics


def test_progress_lines_in_pipes_and_quiet(monkeypatch, capsys) -> None:
    monkeypatch.setattr(_console, "_PLAIN_AFTER_S", 0.0)
    monkeypatch.setattr(sys.stderr, "isatty", lambda: False)
    with _console.progress("detect x.mcap", 4, "scans") as bar:
        for _ in range(4):
            bar.advance(1)
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[0].startswith("detect x.mcap: 1/4 scans, 0 s, about 0 s left")
    assert lines[-1].startswith("detect x.mcap: 4/4 scans, 0 s")
    with _console.progress("detect x.mcap", 4, "scans", quiet=True) as bar:
        bar.advance(4)
    assert capsys.readouterr().err == ""


def test_a_long_first_stage_in_a_pipe_says_what_it_waits_for(monkeypatch, capsys) -> None:
    monkeypatch.setattr(_console, "_PLAIN_WAITING_S", 0.05)
    monkeypatch.setattr(sys.stderr, "isatty", lambda: False)
    with _console.progress("detect x.ply", 3, "stages") as bar:
        bar.advance(0, "compiling kernels (once per install)")
        assert bar._timer is not None
        bar._timer.join(timeout=10)
        bar.advance(3)  # done within a second: no more lines
    assert capsys.readouterr().err.splitlines() == [
        "detect x.ply: 0/3 stages, 0 s (compiling kernels (once per install))"
    ]
    monkeypatch.setattr(_console, "_PLAIN_AFTER_S", 0.0)
    with _console.progress("detect x.ply", 3, "stages") as bar:
        bar.advance(1, "reading")  # a line already: the timer adds none
        bar._timer.join(timeout=10)
    assert capsys.readouterr().err.splitlines() == [
        "detect x.ply: 1/3 stages, 0 s, about 0 s left (reading)"
    ]


def test_progress_bar_on_a_terminal(monkeypatch) -> None:
    import io

    from rich.console import Console

    screen = io.StringIO()
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    monkeypatch.setattr(
        _console, "make_console", lambda **kw: Console(file=screen, force_terminal=True, width=100)
    )
    # A job done within _PLAIN_AFTER_S draws nothing.
    with _console.progress("sim kitchen", 3, "frames") as bar:
        bar.advance(3)
    assert screen.getvalue() == "" and bar._bar is None
    monkeypatch.setattr(_console, "_PLAIN_AFTER_S", 0.0)
    with _console.progress("sim kitchen", 3, "frames") as bar:
        bar.advance(1, "frame 1")
        assert bar._timer is not None
        bar._timer.join(timeout=10)  # the bar starts from what was done meanwhile
        bar.advance(1)
        bar._bar.refresh()
    assert "sim kitchen" in screen.getvalue() and "2/3" in screen.getvalue()
    assert "frame 1" in screen.getvalue()


def test_single_cloud_ctrl_c_says_interrupted(tmp_path: Path, capsys, monkeypatch, rng) -> None:
    path = tmp_path / "p.ply"
    write_ply(path, plane_points(rng, 0, 1, 0, 1, 0.5, 3000))

    def ctrl_c(*args, **kw):
        raise KeyboardInterrupt

    monkeypatch.setattr("supportnode.io.results.write_detection", ctrl_c)
    out = tmp_path / "o"
    assert main(["detect", str(path), "--out", str(out), "--no-objects"]) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"supportnode detect: interrupted while writing: partial output left in {out}/"]
    assert not out.exists()


def _rich_table(columns, rows, left):
    import io

    from rich.console import Console
    from rich.table import Table

    table = Table(box=None, pad_edge=False, title_justify="left", show_edge=False)
    for i, name in enumerate(columns):
        table.add_column(name, justify="left" if i < left else "right", no_wrap=True)
    for row in rows:
        table.add_row(*row)
    screen = io.StringIO()
    Console(file=screen, width=_console._PIPE_WIDTH, highlight=False).print(table)
    return screen.getvalue()


_CELL = st.text(alphabet=st.characters(min_codepoint=32, max_codepoint=126), max_size=12)


@settings(max_examples=400, deadline=None)
@given(
    columns=st.lists(_CELL, min_size=1, max_size=6),
    data=st.data(),
)
def test_plain_tables_in_pipes_are_what_rich_prints(columns, data) -> None:
    n = len(columns)
    rows = data.draw(st.lists(st.lists(_CELL, min_size=n, max_size=n), max_size=6))
    left = data.draw(st.integers(0, n - 1))
    got = _console.plain_table(columns, rows, None, left)
    text = "".join(columns) + "".join(c for r in rows for c in r)
    empty_column = any(not any(r[i] for r in [columns, *rows]) for i in range(n))
    padded = any(c != c.strip() for r in [columns, *rows] for c in r)
    if "[" in text or ":" in text or empty_column or padded:
        assert got is None
    else:
        assert got == _rich_table(columns, rows, left)


def test_plain_tables_leave_the_rest_to_rich(monkeypatch, capsys) -> None:
    assert _console.plain_table(("a", "b"), [["1", "2"]], "title", 1) is None
    assert _console.plain_table(("a", "b"), [["1", "2"]], None, 2) is None  # last column left
    assert _console.plain_table(("a", "b"), [["é", "2"]], None, 1) is None
    assert _console.plain_table(("a",), [["x" * 200]], None, 0) is None
    monkeypatch.setattr(sys.stdout, "isatty", lambda: False)
    _console.print_table(("surface", "points"), [(0, "108,920")])
    assert capsys.readouterr().out == "surface   points\n0        108,920\n"
