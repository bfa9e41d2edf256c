"""Launch files: start several processes, prefix their output, respawn, stop them in order.

A launch file is a YAML list of processes, started in order::

    - name: node                      # unique; prefixes every output line: "[node] ..."
      command: supportnode run        # string (split like a shell) or list
      args: [--verbose]               # appended to the command
      config: ../config/default.yaml  # passed as "--config PATH"
      env: {OMP_NUM_THREADS: 2}       # added to the environment
      cwd: ..                         # working directory (default: the launch file's folder)
      required: true                  # when it exits, everything stops (exit code: its own)
      respawn: false                  # restart it when it exits ...
      respawn_delay: 1.0              # ... after this many seconds
      delay: 0.0                      # seconds to wait before starting it

Commands resolve to the running interpreter, so a launch file works inside any virtualenv: a
leading ``supportnode`` becomes ``python -m supportnode`` and ``python``/``python3`` become
`sys.executable`. Relative paths (``config``, ``cwd``) are relative to the launch file's folder,
which is also the default working directory (so ``args`` paths are too). ``--set key=value``
overrides given to `Launcher` are appended, as ``--set key=value``, to every ``supportnode``
process only (other programs would not understand them).

Parsing is strict like `supportnode.config`: unknown keys, wrong types and missing keys raise
`ConfigError` naming ``file:line``. At run time every child runs in its own process group, so
that Ctrl-C reaches only the launcher, which then stops the children in reverse order (SIGTERM,
SIGKILL after ``stop_timeout``) and returns 0. POSIX only.
"""

from __future__ import annotations

import difflib
import os
import queue
import shlex
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, TextIO

import yaml

from supportnode.errors import ConfigError, SupportNodeError
from supportnode.yamlnodes import (
    BOOL_TAG,
    FLOAT_TAG,
    INT_TAG,
    STR_TAG,
    Constructor,
    compose,
    describe,
    line_of,
    read_text,
)

__all__ = ["LaunchFile", "Launcher", "ProcessSpec", "load_launch", "resolve_command"]

_KEYS = (
    "name",
    "command",
    "args",
    "config",
    "env",
    "cwd",
    "respawn",
    "respawn_delay",
    "required",
    "delay",
)
# Longest the supervisor sleeps between looks at signals (see _supervise), s.
_WAKE_S = 0.25
_SCALAR_TAGS = (STR_TAG, BOOL_TAG, INT_TAG, FLOAT_TAG)


@dataclass(frozen=True)
class ProcessSpec:
    """One process of a launch file, paths resolved to absolute ones."""

    name: str
    command: tuple[str, ...]  # as resolved by `resolve_command`
    args: tuple[str, ...] = ()
    config: str | None = None
    env: dict[str, str] = field(default_factory=dict)
    cwd: str = "."
    respawn: bool = False
    respawn_delay: float = 1.0  # s
    required: bool = False
    delay: float = 0.0  # s
    is_supportnode: bool = False  # a `supportnode ...` command: receives the --set overrides
    where: str = ""  # "file:line" of its entry, for messages

    def argv(self, overrides: Sequence[str] = ()) -> list[str]:
        """The full command line: command, args, ``--config``, then ``--set`` overrides."""
        out = [*self.command, *self.args]
        if self.config is not None:
            out += ["--config", self.config]
        if self.is_supportnode:
            for text in overrides:
                out += ["--set", text]
        return out


@dataclass(frozen=True)
class LaunchFile:
    """A parsed launch file."""

    path: str
    processes: tuple[ProcessSpec, ...]


def resolve_command(command: Sequence[str]) -> tuple[list[str], bool]:
    """``command`` with ``supportnode`` / ``python`` / ``python3`` as the first word replaced by
    the running interpreter; also whether it is a supportnode command."""
    if not command:
        return [], False
    head, rest = command[0], list(command[1:])
    if head == "supportnode":
        return [sys.executable, "-m", "supportnode", *rest], True
    if head in ("python", "python3"):
        if rest[:2] == ["-m", "supportnode"]:
            return [sys.executable, *rest], True
        return [sys.executable, *rest], False
    return list(command), False


# --------------------------------------------------------------------------------------------
# Parsing.


def load_launch(path: str | os.PathLike[str]) -> LaunchFile:
    """Read and check a launch file; raises `ConfigError` with ``file:line`` on any problem."""
    label = os.fspath(path)
    root = compose(read_text(label, ConfigError), label, ConfigError)
    parser = _Parser(label, Path(label).resolve().parent)
    if root is None:
        raise ConfigError(f"{label}: empty launch file (expected a list of processes)")
    if not isinstance(root, yaml.SequenceNode):
        raise parser.fail(root, f"expected a list of processes, got {describe(root)}")
    specs: list[ProcessSpec] = []
    seen: dict[str, str] = {}
    for item in root.value:
        spec = parser.process(item)
        if spec.name in seen:
            raise parser.fail(
                item, f"duplicate process name '{spec.name}' (first at {seen[spec.name]})"
            )
        seen[spec.name] = spec.where
        specs.append(spec)
    if not specs:
        raise parser.fail(root, "no processes to launch")
    return LaunchFile(path=label, processes=tuple(specs))


class _Parser:
    """Checks composed YAML nodes of one launch file."""

    def __init__(self, label: str, folder: Path) -> None:
        self.label = label
        self.folder = folder
        self._values = Constructor()

    def fail(self, node: yaml.Node, message: str) -> ConfigError:
        return ConfigError(f"{self.label}:{line_of(node)}: {message}")

    def process(self, node: yaml.Node) -> ProcessSpec:
        if not isinstance(node, yaml.MappingNode):
            raise self.fail(node, f"expected a process (a mapping of keys), got {describe(node)}")
        values: dict[str, tuple[yaml.Node, yaml.Node]] = {}
        for key_node, value_node in node.value:
            key = str(key_node.value) if isinstance(key_node, yaml.ScalarNode) else "?"
            if key not in _KEYS:
                close = difflib.get_close_matches(key, _KEYS, n=1)
                hint = f"did you mean '{close[0]}'?" if close else "known keys: " + ", ".join(_KEYS)
                raise self.fail(key_node, f"unknown key '{key}' ({hint})")
            if key in values:
                raise self.fail(key_node, f"duplicate key '{key}'")
            values[key] = (key_node, value_node)
        for key in ("name", "command"):
            if key not in values:
                raise self.fail(node, f"process without '{key}'")
        name = self.text(values["name"][1], "name")
        if not name or any(c.isspace() for c in name):
            raise self.fail(values["name"][1], f"name: expected one word, got {name!r}")
        where = f"{self.label}:{node.start_mark.line + 1}"
        command_node = values["command"][1]
        if isinstance(command_node, yaml.SequenceNode):
            words = self.words(command_node, "command")
        else:
            try:
                words = shlex.split(self.text(command_node, "command"))
            except ValueError as err:
                raise self.fail(command_node, f"command: {err}") from err
        if not words:
            raise self.fail(command_node, "command: empty")
        command, is_supportnode = resolve_command(words)
        opt: dict[str, Any] = {}
        if "args" in values:
            opt["args"] = tuple(self.words(values["args"][1], "args"))
        if "config" in values:
            config = self.text(values["config"][1], "config")
            opt["config"] = os.path.normpath(self.folder / config)
        if "env" in values:
            opt["env"] = self.env(values["env"][1])
        cwd = self.text(values["cwd"][1], "cwd") if "cwd" in values else "."
        opt["cwd"] = os.path.normpath(self.folder / cwd)
        for key in ("respawn", "required"):
            if key in values:
                opt[key] = self.boolean(values[key][1], key)
        for key in ("respawn_delay", "delay"):
            if key in values:
                opt[key] = self.seconds(values[key][1], key)
        if opt.get("respawn") and opt.get("required"):
            raise self.fail(node, f"process '{name}': respawn and required exclude each other")
        return ProcessSpec(
            name=name,
            command=tuple(command),
            is_supportnode=is_supportnode,
            where=where,
            **opt,
        )

    def value(self, node: yaml.ScalarNode) -> Any:
        return self._values.value(node)

    def text(self, node: yaml.Node, key: str) -> str:
        if not isinstance(node, yaml.ScalarNode) or node.tag != STR_TAG:
            raise self.fail(node, f"{key}: expected a string, got {describe(node)}")
        return str(node.value)

    def words(self, node: yaml.Node, key: str) -> list[str]:
        """A list of scalars, each taken as written (``0.10`` stays ``0.10``)."""
        if not isinstance(node, yaml.SequenceNode):
            raise self.fail(node, f"{key}: expected a list, got {describe(node)}")
        out = []
        for item in node.value:
            if not isinstance(item, yaml.ScalarNode) or item.tag not in _SCALAR_TAGS:
                raise self.fail(item, f"{key}: expected strings or numbers, got {describe(item)}")
            out.append(str(item.value))
        return out

    def env(self, node: yaml.Node) -> dict[str, str]:
        if not isinstance(node, yaml.MappingNode):
            raise self.fail(node, f"env: expected a mapping NAME: value, got {describe(node)}")
        out: dict[str, str] = {}
        for key_node, value_node in node.value:
            name = str(key_node.value) if isinstance(key_node, yaml.ScalarNode) else ""
            if not name or "=" in name:
                raise self.fail(key_node, f"env: bad variable name {name!r}")
            if not isinstance(value_node, yaml.ScalarNode) or value_node.tag not in _SCALAR_TAGS:
                raise self.fail(value_node, f"env.{name}: expected a string or number")
            out[name] = str(value_node.value)
        return out

    def boolean(self, node: yaml.Node, key: str) -> bool:
        if not isinstance(node, yaml.ScalarNode) or node.tag != BOOL_TAG:
            raise self.fail(node, f"{key}: expected true or false, got {describe(node)}")
        return bool(self.value(node))

    def seconds(self, node: yaml.Node, key: str) -> float:
        if not isinstance(node, yaml.ScalarNode) or node.tag not in (INT_TAG, FLOAT_TAG):
            raise self.fail(node, f"{key}: expected a number of seconds, got {describe(node)}")
        value = float(self.value(node))
        if not (0.0 <= value < float("inf")):
            raise self.fail(node, f"{key}: expected a finite number >= 0 s, got {node.value}")
        return value


# --------------------------------------------------------------------------------------------
# Running.


@dataclass
class _Running:
    """A started process and the threads copying its output."""

    spec: ProcessSpec
    proc: subprocess.Popen[bytes]
    readers: list[threading.Thread]


class Launcher:
    """Runs a `LaunchFile` until a required process exits, everything has exited or `stop`.

    ``out`` / ``err``: where prefixed child stdout / stderr lines (and the launcher's own
    ``[launch]`` messages, on ``err``) are written.
    """

    def __init__(
        self,
        launch: LaunchFile,
        overrides: Sequence[str] = (),
        *,
        stop_timeout: float = 5.0,
        out: TextIO | None = None,
        err: TextIO | None = None,
    ) -> None:
        self.launch = launch
        self.overrides = list(overrides)
        self.stop_timeout = stop_timeout
        self.out = out if out is not None else sys.stdout
        self.err = err if err is not None else sys.stderr
        self.restarts: dict[str, int] = {p.name: 0 for p in launch.processes}
        self._events: queue.SimpleQueue[tuple[str, Any]] = queue.SimpleQueue()
        self._running: dict[str, _Running] = {}
        self._write_lock = threading.Lock()
        self._output_gone = False

    # Thread- and signal-safe: SimpleQueue.put may be called from a signal handler.
    def stop(self) -> None:
        """Ask `run` to stop every process and return 0."""
        self._events.put(("stop", None))

    @property
    def output_gone(self) -> bool:
        """True once writing the output failed because its reader went away."""
        return self._output_gone

    def log(self, message: str) -> None:
        """One ``[launch]`` line on the error stream."""
        self._write(self.err, f"[launch] {message}\n")

    def _write(self, stream: TextIO, text: str) -> None:
        with self._write_lock:
            if self._output_gone:
                return
            try:
                stream.write(text)
                stream.flush()
            except (BrokenPipeError, ValueError):
                # Whoever read the output is gone (`supportnode launch ... | head`, a closed
                # terminal): stop everything, as the reader's end of a pipe means, instead of
                # dying in the middle and leaving the children (own sessions) running.
                self._output_gone = True
                self._events.put(("stop", None))

    def run(self) -> int:
        """Start the processes and supervise them; returns the exit code for the launcher.

        0 after `stop` (or SIGINT/SIGTERM, handled while running in the main thread); a
        required process's own code when it exits (128+N if killed by signal N); when every
        process has ended by itself, 0 if all succeeded, else 1.
        """
        restore = self._install_signal_handlers()
        try:
            return self._supervise()
        finally:
            self._stop_all()
            for sig, handler in restore.items():
                signal.signal(sig, handler)

    def _install_signal_handlers(self) -> dict[int, Any]:
        if threading.current_thread() is not threading.main_thread():
            return {}
        previous: dict[int, Any] = {}
        for sig in (signal.SIGINT, signal.SIGTERM):
            previous[sig] = signal.signal(sig, lambda signum, frame: self.stop())
        return previous

    def _supervise(self) -> int:
        specs = list(self.launch.processes)
        # (due time, spec, is a restart) of processes waiting to start, in start order.
        schedule: list[tuple[float, ProcessSpec, bool]] = []
        start_at = time.monotonic()
        for spec in specs:
            start_at += spec.delay  # each delay counts from the previous start
            schedule.append((start_at, spec, False))
        failed = False
        while True:
            now = time.monotonic()
            while schedule and schedule[0][0] <= now:
                _, spec, restart = schedule.pop(0)
                if restart:
                    self.restarts[spec.name] += 1
                self._start(spec)
            if not schedule and not self._running:
                self.log("every process has exited")
                return 1 if failed else 0
            # Never an unbounded wait: a SIGINT or SIGTERM that the kernel hands to one of the
            # reader threads only sets a flag, and its handler runs in this (main) thread once
            # it next wakes; a wait without end would never see it.
            timeout = min(max(0.0, schedule[0][0] - now), _WAKE_S) if schedule else _WAKE_S
            try:
                kind, payload = self._events.get(timeout=timeout)
            except queue.Empty:
                continue
            if kind == "stop":
                self.log("stopping")
                return 0
            running: _Running = payload
            if self._running.get(running.spec.name) is not running:
                continue  # stale
            del self._running[running.spec.name]
            code = running.proc.returncode
            spec = running.spec
            self.log(f"{spec.name} exited with code {_describe_code(code)}")
            if spec.required:
                self.log(f"{spec.name} is required: stopping the others")
                return _exit_status(code)
            if spec.respawn:
                self.log(
                    f"restarting {spec.name} in {spec.respawn_delay:g} s "
                    f"(restart {self.restarts[spec.name] + 1})"
                )
                due = time.monotonic() + spec.respawn_delay
                schedule.append((due, spec, True))
                schedule.sort(key=lambda item: item[0])
            elif code != 0:
                failed = True

    def _start(self, spec: ProcessSpec) -> None:
        argv = spec.argv(self.overrides)
        env = {**os.environ, **spec.env}
        env.setdefault("PYTHONUNBUFFERED", "1")  # children's lines show up as they are printed
        try:
            proc = subprocess.Popen(
                argv,
                cwd=spec.cwd,
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                # Own process group: a terminal's Ctrl-C reaches only the launcher, which
                # stops the children itself, in reverse order.
                start_new_session=True,
            )
        except OSError as err:
            raise SupportNodeError(
                f"{spec.where}: cannot start '{spec.name}' ({shlex.join(argv)}): {err.strerror}"
            ) from err
        readers = [
            threading.Thread(target=self._copy, args=(spec.name, pipe, stream), daemon=True)
            for pipe, stream in ((proc.stdout, self.out), (proc.stderr, self.err))
        ]
        running = _Running(spec, proc, readers)
        self._running[spec.name] = running
        for reader in readers:
            reader.start()
        threading.Thread(target=self._wait, args=(running,), daemon=True).start()
        again = f", restart {self.restarts[spec.name]}" if self.restarts[spec.name] else ""
        self.log(f"started {spec.name} (pid {proc.pid}{again}): {shlex.join(argv)}")

    def _copy(self, name: str, pipe: IO[bytes] | None, stream: TextIO) -> None:
        """Copy one child pipe line by line to ``stream``, each line prefixed with ``[name]``."""
        if pipe is None:
            return
        with pipe:
            for raw in iter(pipe.readline, b""):
                line = raw.decode("utf-8", errors="replace").rstrip("\r\n")
                self._write(stream, f"[{name}] {line}\n")

    def _wait(self, running: _Running) -> None:
        running.proc.wait()
        for reader in running.readers:
            reader.join(timeout=1.0)  # its last lines come before the "exited" message
        self._events.put(("exit", running))

    def _stop_all(self) -> None:
        """Stop what still runs in reverse launch-file order (a respawned process keeps its
        place): SIGTERM, SIGKILL after ``stop_timeout``."""
        for spec in reversed(self.launch.processes):
            name = spec.name
            if name not in self._running:
                continue
            running = self._running.pop(name)
            proc = running.proc
            if proc.poll() is None:
                self.log(f"stopping {name} (pid {proc.pid})")
                _signal_group(proc, signal.SIGTERM)
                try:
                    proc.wait(timeout=self.stop_timeout)
                except subprocess.TimeoutExpired:
                    self.log(f"{name} did not stop in {self.stop_timeout:g} s: killing it")
                    _signal_group(proc, signal.SIGKILL)
                    proc.wait()
            for reader in running.readers:
                reader.join(timeout=1.0)
            self.log(f"{name} stopped with code {_describe_code(proc.returncode)}")


def _signal_group(proc: subprocess.Popen[bytes], sig: int) -> None:
    """Signal the child's whole process group (its own children too), else just the child."""
    try:
        os.killpg(proc.pid, sig)
    except (ProcessLookupError, PermissionError):
        try:
            proc.send_signal(sig)
        except ProcessLookupError:
            pass


def _describe_code(code: int | None) -> str:
    if code is not None and code < 0:
        try:
            return f"{code} ({signal.Signals(-code).name})"
        except ValueError:
            return str(code)
    return str(code)


def _exit_status(code: int | None) -> int:
    """A child's return code as a shell would report it (128+N for a signal)."""
    if code is None:
        return 1
    return 128 - code if code < 0 else code
