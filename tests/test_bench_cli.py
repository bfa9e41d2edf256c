"""The node benchmark's command line: a wrong flag value is a one-line error, exit code 2."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parent.parent / "bench" / "bench_node.py"


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--noise", "-1"], "--noise: expected a finite number >= 0, got -1.0"),
        (["--noise", "nan"], "--noise: expected a finite number >= 0, got nan"),
        (["--only", "e2e,bogus"], "--only: unknown part(s) bogus"),
        (["--map-points", "centroid"], "argument --map-points: invalid choice: 'centroid'"),
        (
            ["--set", "node.map.radiuss=3"],
            "unknown key 'node.map.radiuss' (did you mean 'radius'?)",
        ),
        (["--set", "node.scan_bind=maybe"], "node.scan_bind: expected true or false"),
    ],
)
def test_bad_flags_are_one_line_errors(args, message):
    proc = subprocess.run(
        [sys.executable, str(BENCH), *args], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 2
    last = proc.stderr.strip().splitlines()[-1]
    assert last.startswith("bench_node.py: error: ") and message in last
    assert "Traceback" not in proc.stderr and proc.stdout == ""


AB = BENCH.parent / "ab.py"


def test_ab_pairs_two_sides_and_reports_medians_and_differences(tmp_path):
    """bench/ab.py runs both sides by turns and reports each number of the script's JSON
    lines: median of A, of B, and the paired difference."""
    script = tmp_path / "fake_bench.py"
    script.write_text(
        "import json, sys\n"
        "v = float(sys.argv[sys.argv.index('--v') + 1])\n"
        "print('not json')\n"
        "print(json.dumps({'e2e': {'latency': {'p50_ms': v, 'p99_ms': 2 * v}, 'ok': True}}))\n"
    )
    proc = subprocess.run(
        [sys.executable, str(AB), "--reps", "2", "--a-args", "--v 10", "--b-args", "--v 7",
         "--keys", "p50,p99", "--", str(script)],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    rows = {ln.split()[0]: ln.split()[1:] for ln in proc.stdout.splitlines() if "latency" in ln}
    assert [float(x) for x in rows["e2e.latency.p50_ms"]] == [10.0, 7.0, -3.0, 0.7]
    assert [float(x) for x in rows["e2e.latency.p99_ms"]] == [20.0, 14.0, -6.0, 0.7]
    assert "e2e.ok" not in proc.stdout


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--a", "no-such-revision", "--", str(BENCH)], "--a no-such-revision"),
        (["--", "bench/missing.py"], "no such script: bench/missing.py"),
        (["--reps", "0", "--", str(BENCH)], "--reps: expected at least 1, got 0"),
        ([], "no benchmark script"),
    ],
)
def test_ab_bad_arguments_are_one_line_errors(args, message):
    proc = subprocess.run(
        [sys.executable, str(AB), *args], capture_output=True, text=True, timeout=60
    )
    assert proc.returncode != 0 and message in proc.stderr.strip().splitlines()[-1]
    assert "Traceback" not in proc.stderr


@pytest.mark.parametrize(
    ("script", "args", "message"),
    [
        ("bench_compiled.py", ["--scans", "0"], "--scans and --repeats must be at least 1"),
        ("bench_compiled.py", ["--repeats", "-2"], "--scans and --repeats must be at least 1"),
        ("bench_locality.py", ["--from-scan", "59"], "--from-scan must be at least 0 and below"),
        ("bench_locality.py", ["--margin", "nan"], "--margin: expected a finite number >= 0"),
        ("real_accuracy.py", ["--decimate", "0"], "--every and --decimate must be at least 1"),
        ("real_accuracy.py", ["--every", "-1"], "--every and --decimate must be at least 1"),
        ("bench_startup.py", ["--runs", "0"], "--runs must be at least 1, got 0"),
        ("bench_startup.py", ["nope.ply"], "nope.ply: no such file"),
        ("bench_startup.py", ["--baseline", "no-such-rev"], "--baseline no-such-rev: not a"),
        ("bench_startup.py", ["--cold", "-1"], "--cold must be at least 0, got -1"),
        ("bench_objects.py", ["--repeats", "0"], "--repeats must be at least 1, got 0"),
    ],
)
def test_other_bench_scripts_bad_flags_are_one_line_errors(script, args, message):
    proc = subprocess.run(
        [sys.executable, str(BENCH.parent / script), *args],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 2
    last = proc.stderr.strip().splitlines()[-1]
    assert last.startswith(f"{script}: error: ") and message in last
    assert "Traceback" not in proc.stderr and proc.stdout == ""


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--repeats", "0"], "--repeats must be at least 1, got 0"),
        (["nope.pcd"], "nope.pcd: no such file"),
    ],
)
def test_bench_io_bad_flags_are_one_line_errors(args, message):
    proc = subprocess.run(
        [sys.executable, str(BENCH.parent / "bench_io.py"), *args],
        capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines()[-1] == f"bench_io.py: error: {message}"
