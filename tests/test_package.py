"""What a pip user gets: the top-level help, --version, config dump, shipped launch files, and
(slow) an sdist and wheel from `python -m build` that install and run the demo in a fresh venv
outside the repository."""

from __future__ import annotations

import os
import subprocess
import sys
import venv
import zipfile
from pathlib import Path

import pytest
import yaml
from conftest import run_cli

from supportnode import __version__
from supportnode.config import load_config

REPO = Path(__file__).resolve().parents[1]


def test_top_level_help_is_for_users_with_examples() -> None:
    proc = run_cli("--help")
    assert proc.returncode == 0
    assert "support surfaces" in proc.stdout
    assert "examples:" in proc.stdout and "supportnode launch demo" in proc.stdout
    assert "dispatches" not in proc.stdout  # not the developer docstring
    bare = run_cli()
    assert bare.returncode == 2 and "examples:" in bare.stdout
    assert run_cli("--version").stdout.strip() == f"supportnode {__version__}"


def test_config_dump_writes_the_full_default_config(tmp_path: Path) -> None:
    proc = run_cli("config", "dump")
    assert proc.returncode == 0
    assert proc.stdout == (REPO / "config" / "default.yaml").read_text()
    out = tmp_path / "my.yaml"
    assert run_cli("config", "dump", "-o", str(out)).returncode == 0
    assert load_config(out) == load_config(None)
    noisy = run_cli("config", "dump", "noisy")
    assert noisy.stdout == (REPO / "config" / "noisy.yaml").read_text()
    bad = run_cli("config", "dump", "nosuch")
    assert bad.returncode == 2
    assert bad.stderr.strip().splitlines() == [
        "supportnode config: error: no shipped config file 'nosuch' (there are: default, noisy, "
        "report)"
    ]


def test_launch_takes_a_shipped_name_from_any_folder(tmp_path: Path) -> None:
    proc = run_cli("launch", "demo", "--check", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "table_chairs_lidar.mcap" in proc.stdout and "planner.py" in proc.stdout
    listed = run_cli("config", "list").stdout
    assert "launch  demo" in listed and "config  default" in listed
    bad = run_cli("launch", "demo2", cwd=tmp_path)
    assert bad.returncode == 2
    assert "no shipped launch file 'demo2' (there are: demo, example_pubsub)" in bad.stderr


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_built_wheel_installs_and_runs_the_demo_outside_the_repo(tmp_path: Path) -> None:
    pytest.importorskip("build")
    dist = tmp_path / "dist"
    subprocess.run(
        [sys.executable, "-m", "build", "--outdir", str(dist), str(REPO)],
        check=True,
        capture_output=True,
        timeout=600,
    )
    assert len(list(dist.glob("supportnode-*.tar.gz"))) == 1
    (wheel,) = dist.glob("supportnode-*.whl")  # built from the sdist: both are checked
    with zipfile.ZipFile(wheel) as zf:  # type checkers see the package's annotations (PEP 561)
        assert "supportnode/py.typed" in zf.namelist()
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=True)
    bin_dir = env_dir / "bin"
    subprocess.run(
        [bin_dir / "python", "-m", "pip", "install", "-q", str(wheel)],
        check=True,
        capture_output=True,
        timeout=600,
    )
    home = tmp_path / "user"
    home.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"

    def run(*args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            [str(bin_dir / "supportnode"), *args],
            cwd=home,
            env=env,
            capture_output=True,
            text=True,
            timeout=timeout,
        )

    assert run("--version").stdout.strip() == f"supportnode {__version__}"
    dumped = yaml.safe_load(run("config", "dump").stdout)
    assert dumped["safe"]["min_area"] == 0.1 and "node" in dumped
    # the package itself comes from the venv, not from this checkout
    where = subprocess.run(
        [bin_dir / "python", "-c", "import supportnode; print(supportnode.__file__)"],
        cwd=home,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert str(env_dir) in where
    demo = run("launch", "demo", "--duration", "60", timeout=300)
    assert demo.returncode == 0, demo.stderr[-2000:]
    lines = [
        ln for ln in demo.stdout.splitlines() if ln.startswith("[planner]") and "safe of" in ln
    ]
    assert lines, demo.stdout[-2000:] + demo.stderr[-2000:]


def test_output_into_a_closed_pipe_is_no_traceback(monkeypatch, capsys) -> None:
    # `supportnode info REC | head -1`: the reader is gone before the summary is printed
    from supportnode.cli import main

    read_end, write_end = os.pipe()
    os.close(read_end)
    closed = os.fdopen(write_end, "w", buffering=1)
    monkeypatch.setattr(sys, "stdout", closed)
    try:
        assert main(["info", str(REPO / "sim_scans" / "shelf_lidar.mcap")]) == 0
    finally:
        monkeypatch.undo()
        closed.close()
    assert "Traceback" not in capsys.readouterr().err
