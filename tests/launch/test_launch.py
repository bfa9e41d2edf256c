"""Launch files: strict parsing with file:line errors, prefixed output, required and respawning
processes, and stopping in reverse order on SIGTERM / SIGINT."""

from __future__ import annotations

import io
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from supportnode.errors import ConfigError
from supportnode.launch import Launcher, load_launch, resolve_command

REPO = Path(__file__).resolve().parents[2]

# A child that announces itself, then waits; on SIGTERM it appends its name to stopped.txt
# (so the test sees the stop order) unless told to ignore SIGTERM.
CHILD = """\
import pathlib, signal, sys, time
name, folder = sys.argv[1], pathlib.Path(sys.argv[2])
def stop(signum, frame):
    with open(folder / "stopped.txt", "a") as fh:
        fh.write(name + "\\n")
    print(name, "stopping", flush=True)
    sys.exit(0)
if "--ignore-term" in sys.argv:
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
else:
    signal.signal(signal.SIGTERM, stop)
print(name, "up", flush=True)
print(name, "to stderr", file=sys.stderr, flush=True)
(folder / ("started_" + name)).touch()
time.sleep(60)
"""


TICK = """for i in range(600):
    print(name, "tick", i, flush=True)
    time.sleep(0.1)"""


def write(path: Path, text: str) -> Path:
    path.write_text(textwrap.dedent(text))
    return path


# ---------------------------------------------------------------------------------------------
# Parsing


def test_parse_resolves_commands_and_paths(tmp_path):
    (tmp_path / "cfg").mkdir()
    f = write(
        tmp_path / "l.yaml",
        """\
        - name: node
          command: supportnode run --verbose
          config: cfg/node.yaml
          required: true
        - name: planner
          command: [python3, ../planner.py]
          args: [--radius, 0.10, 3]
          env: {A: 1, B: text}
          cwd: cfg
          respawn: true
          respawn_delay: 0.5
          delay: 2
        - name: tool
          command: /bin/echo hi
        """,
    )
    launch = load_launch(f)
    node, planner, tool = launch.processes
    assert node.command == (sys.executable, "-m", "supportnode", "run", "--verbose")
    assert node.is_supportnode and node.required and not node.respawn
    assert node.config == str(tmp_path / "cfg" / "node.yaml")
    assert node.cwd == str(tmp_path)
    assert node.argv(["a.b=1"]) == [
        *node.command,
        "--config",
        node.config,
        "--set",
        "a.b=1",
    ]
    assert planner.command == (sys.executable, "../planner.py")
    assert planner.args == ("--radius", "0.10", "3")  # as written, not 0.1
    assert planner.env == {"A": "1", "B": "text"}
    assert planner.cwd == str(tmp_path / "cfg")
    assert (planner.respawn, planner.respawn_delay, planner.delay) == (True, 0.5, 2.0)
    assert planner.argv(["a.b=1"]) == [*planner.command, *planner.args]  # no --set
    assert tool.command == ("/bin/echo", "hi") and not tool.is_supportnode


def test_resolve_command():
    assert resolve_command(["python", "-m", "supportnode", "sim"]) == (
        [sys.executable, "-m", "supportnode", "sim"],
        True,
    )
    assert resolve_command(["pythonx"]) == (["pythonx"], False)


@pytest.mark.parametrize(
    "text, message",
    [
        (
            "- name: a\n  command: x\n  comand: y\n",
            r"l\.yaml:3: unknown key 'comand' \(did you mean 'command'\?\)",
        ),
        ("- name: a\n  args: [x]\n", r"l\.yaml:1: process without 'command'"),
        ("- command: x\n", r"l\.yaml:1: process without 'name'"),
        ("- name: a\n  command: []\n", r"l\.yaml:2: command: empty"),
        ("- name: a\n  command: x\n  respawn: yes please\n", r"l\.yaml:3: respawn: expected true"),
        ("- name: a\n  command: x\n  delay: -1\n", r"l\.yaml:3: delay: expected a finite number"),
        ("- name: a\n  command: x\n  args: x\n", r"l\.yaml:3: args: expected a list"),
        ("- name: a\n  command: x\n  env: [1]\n", r"l\.yaml:3: env: expected a mapping"),
        (
            "- name: a\n  command: x\n- name: a\n  command: y\n",
            r"l\.yaml:3: duplicate process name 'a' \(first at .*l\.yaml:1\)",
        ),
        (
            "- name: a\n  command: x\n  respawn: true\n  required: true\n",
            r"l\.yaml:1: process 'a': respawn and required exclude each other",
        ),
        ("name: a\ncommand: x\n", r"l\.yaml:1: expected a list of processes, got a mapping"),
        ("", r"l\.yaml: empty launch file"),
        ("- name: a\n  command: 'x\n", r"l\.yaml:\d+: YAML syntax error"),
        ('- name: a\n  command: "x \'y"\n', r"l\.yaml:2: command: No closing quotation"),
    ],
)
def test_parse_errors(tmp_path, text, message):
    f = tmp_path / "l.yaml"
    f.write_text(text)
    with pytest.raises(ConfigError, match=message):
        load_launch(f)


def test_missing_file(tmp_path):
    with pytest.raises(ConfigError, match="no such file"):
        load_launch(tmp_path / "nope.yaml")


# ---------------------------------------------------------------------------------------------
# Running in-process


def run_launcher(path: Path, **kw) -> tuple[int, str, str, Launcher]:
    out, err = io.StringIO(), io.StringIO()
    launcher = Launcher(load_launch(path), out=out, err=err, stop_timeout=2.0, **kw)
    t0 = time.monotonic()
    code = launcher.run()
    assert time.monotonic() - t0 < 10
    return code, out.getvalue(), err.getvalue(), launcher


def test_signal_taken_by_another_thread_still_stops_the_launcher(tmp_path):
    """The kernel may hand a SIGINT to any thread of the launcher (its output readers); the
    handler then runs in the main thread only once it wakes. The supervisor must not sleep
    until some child happens to exit: it stops within a second."""
    import threading

    write(tmp_path / "child.py", CHILD)
    f = write(tmp_path / "l.yaml", "- name: a\n  command: python child.py a .\n")
    out, err = io.StringIO(), io.StringIO()
    launcher = Launcher(load_launch(f), out=out, err=err, stop_timeout=2.0)
    sent: list[float] = []

    def interrupt_from_a_worker_thread() -> None:
        deadline = time.monotonic() + 10
        while not (tmp_path / "started_a").exists() and time.monotonic() < deadline:
            time.sleep(0.02)
        sent.append(time.monotonic())
        signal.pthread_kill(threading.get_ident(), signal.SIGINT)  # to this thread, not main
        time.sleep(5)
        launcher.stop()  # the fallback, so that a failing launcher still ends

    threading.Thread(target=interrupt_from_a_worker_thread, daemon=True).start()
    assert launcher.run() == 0
    assert time.monotonic() - sent[0] < 1.0, err.getvalue()
    assert (tmp_path / "stopped.txt").read_text() == "a\n"


def test_required_exit_stops_the_others_and_output_is_prefixed(tmp_path):
    write(tmp_path / "child.py", CHILD)
    f = write(
        tmp_path / "l.yaml",
        """\
        - name: waiter
          command: python child.py waiter .
        - name: boss
          command: python boss.py
          required: true
        """,
    )
    write(
        tmp_path / "boss.py",
        """\
        import pathlib, time
        print("boss says hi")
        while not pathlib.Path("started_waiter").exists():
            time.sleep(0.01)
        raise SystemExit(3)
        """,
    )
    code, out, err, _ = run_launcher(f)
    assert code == 3
    assert "[waiter] waiter up\n" in out and "[boss] boss says hi\n" in out
    assert "[waiter] waiter to stderr\n" in err
    assert "[launch] boss exited with code 3" in err
    # The waiter was stopped by SIGTERM (its handler ran), not left behind.
    assert (tmp_path / "stopped.txt").read_text() == "waiter\n"
    assert "[waiter] waiter stopping\n" in out


def test_required_exit_zero_returns_zero(tmp_path):
    f = write(
        tmp_path / "l.yaml",
        """\
        - name: ok
          command: python -c "pass"
          required: true
        """,
    )
    assert run_launcher(f)[0] == 0


def test_respawn_restarts_are_counted(tmp_path):
    f = write(
        tmp_path / "l.yaml",
        """\
        - name: flaky
          command: [python, -c, "print('flaky run')"]
          respawn: true
          respawn_delay: 0.05
        - name: boss
          command: python -c "import time; time.sleep(0.8)"
          required: true
        """,
    )
    code, out, err, launcher = run_launcher(f)
    assert code == 0
    restarts = launcher.restarts["flaky"]
    assert restarts >= 2
    # Every run that ended by itself printed its line (the last one may have been stopped).
    finished = err.count("[launch] flaky exited with code 0")
    assert finished in (restarts, restarts + 1)
    assert out.count("[flaky] flaky run\n") >= finished
    assert f"restarting flaky in 0.05 s (restart {restarts})" in err


def test_all_exited_without_required(tmp_path):
    f = write(
        tmp_path / "l.yaml",
        """\
        - name: good
          command: python -c "pass"
        - name: bad
          command: python -c "raise SystemExit(4)"
          delay: 0.05
        """,
    )
    code, _, err, _ = run_launcher(f)
    assert code == 1
    assert "every process has exited" in err


def test_start_failure_names_the_entry(tmp_path):
    f = write(tmp_path / "l.yaml", "- name: ghost\n  command: /no/such/program\n")
    with pytest.raises(Exception, match=r"l\.yaml:1: cannot start 'ghost'"):
        run_launcher(f)


# ---------------------------------------------------------------------------------------------
# `supportnode launch` as a subprocess, stopped by a signal


def start_cli(tmp_path: Path, *extra: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "supportnode", "launch", str(tmp_path / "l.yaml"), *extra],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=REPO,
    )


def wait_for(paths: list[Path], proc: subprocess.Popen[str], timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not all(p.exists() for p in paths):
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            out, err = proc.communicate()
            raise AssertionError(f"children did not start:\n{out}\n{err}")
        time.sleep(0.02)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_stops_children_in_reverse_order(tmp_path, sig):
    write(tmp_path / "child.py", CHILD)
    write(
        tmp_path / "l.yaml",
        """\
        - name: a
          command: python child.py a .
        - name: b
          command: python child.py b .
        - name: c
          command: python child.py c .
        """,
    )
    proc = start_cli(tmp_path)
    wait_for([tmp_path / f"started_{n}" for n in "abc"], proc)
    t0 = time.monotonic()
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=15)
    assert proc.returncode == 0, err
    assert time.monotonic() - t0 < 5, (out, err)
    assert (tmp_path / "stopped.txt").read_text() == "c\nb\na\n"
    assert "[a] a up" in out and "[c] c stopping" in out


def test_duration_stops_everything_and_exits_0(tmp_path):
    write(tmp_path / "child.py", CHILD)
    write(tmp_path / "l.yaml", "- name: a\n  command: python child.py a .\n")
    proc = start_cli(tmp_path, "--duration", "1.5")
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 0, err
    assert (tmp_path / "stopped.txt").read_text() == "a\n"


def test_reader_gone_stops_the_children(tmp_path):
    """`supportnode launch ... | head -1`: when the output's reader goes away, the launcher
    stops its children (they run in their own sessions) and exits, not dies and orphans them."""
    # A child that keeps talking, like the node: the launcher notices at its next line.
    write(tmp_path / "child.py", CHILD.replace("time.sleep(60)", TICK))
    write(tmp_path / "l.yaml", "- name: a\n  command: python child.py a .\n")
    proc = start_cli(tmp_path)
    wait_for([tmp_path / "started_a"], proc)
    proc.stdout.close()  # the reader of both streams goes away
    proc.stderr.close()
    proc.wait(timeout=20)
    deadline = time.monotonic() + 10
    while not (tmp_path / "stopped.txt").exists() and time.monotonic() < deadline:
        time.sleep(0.05)
    assert (tmp_path / "stopped.txt").read_text() == "a\n"


def test_bad_duration_is_one_line_exit_2(tmp_path):
    write(tmp_path / "l.yaml", "- name: a\n  command: python -c pass\n")
    proc = start_cli(tmp_path, "--duration", "soon")
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 2 and "--duration" in err and "Traceback" not in err


def test_sigkill_after_stop_timeout(tmp_path):
    write(tmp_path / "child.py", CHILD)
    write(
        tmp_path / "l.yaml",
        "- name: stubborn\n  command: python child.py stubborn . --ignore-term\n",
    )
    proc = start_cli(tmp_path, "--stop-timeout", "0.3")
    wait_for([tmp_path / "started_stubborn"], proc)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=10)
    assert proc.returncode == 0
    assert "stubborn did not stop in 0.3 s: killing it" in err
    assert "SIGKILL" in err


def test_cli_check_and_bad_override(tmp_path):
    write(
        tmp_path / "l.yaml",
        "- name: n\n  command: supportnode run\n- name: p\n  command: python p.py\n",
    )
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "supportnode",
            "launch",
            str(tmp_path / "l.yaml"),
            "--check",
            "--set",
            "node.detection_rate=2",
        ],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=30,
    )
    assert result.returncode == 0, result.stderr
    assert f"n: {sys.executable} -m supportnode run --set node.detection_rate=2\n" in result.stdout
    assert f"p: {sys.executable} p.py\n" in result.stdout
    result = subprocess.run(
        [sys.executable, "-m", "supportnode", "launch", str(tmp_path / "l.yaml"), "--set", "oops"],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=30,
    )
    assert result.returncode == 2
    assert "expected key=value" in result.stderr


def test_repo_launch_files_parse():
    for path in sorted((REPO / "launch").glob("*.yaml")):
        launch = load_launch(path)
        assert launch.processes, path
        for spec in launch.processes:
            assert os.path.isdir(spec.cwd), spec


def test_example_pubsub_launch_file_runs(tmp_path):
    """launch/example_pubsub.yaml as shipped, moved to a free port (tests may run in parallel)."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    text = (REPO / "launch" / "example_pubsub.yaml").read_text()
    text = text.replace("tcp://127.0.0.1:5555", f"tcp://127.0.0.1:{port}")
    text = text.replace("../", f"{REPO}/")
    (tmp_path / "l.yaml").write_text(text)
    proc = start_cli(tmp_path)
    lines: list[str] = []
    deadline = time.monotonic() + 20
    assert proc.stdout is not None
    for line in proc.stdout:  # ends when the launcher exits
        lines.append(line)
        if line.startswith("[echo] scan PointCloud") or time.monotonic() > deadline:
            break
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=15)
    assert proc.returncode == 0, err
    assert any(s.startswith("[scans] publish_scans: ") for s in lines), lines
    assert "points with pose" in lines[-1], lines
    assert "echo stopped with code 0" in err and "scans stopped with code 0" in err
