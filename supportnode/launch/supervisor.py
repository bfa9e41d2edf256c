"""Running a launch file: start the processes in order, prefix their output, respawn, stop them
in reverse order on a signal or when a required process exits (POSIX process groups)."""

from __future__ import annotations

import os
import queue
import shlex
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import IO, Any, TextIO

from supportnode.errors import SupportNodeError
from supportnode.launch.spec import LaunchFile, ProcessSpec

__all__ = ["Launcher"]

# Longest the supervisor sleeps between looks at signals (see _supervise), s.
_WAKE_S = 0.25

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
