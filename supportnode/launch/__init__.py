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

from supportnode.launch.spec import LaunchFile, ProcessSpec, load_launch, resolve_command
from supportnode.launch.supervisor import Launcher

__all__ = ["LaunchFile", "Launcher", "ProcessSpec", "load_launch", "resolve_command"]
