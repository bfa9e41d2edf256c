"""The collector policy of a command's process (supportnode.cli._process)."""

from __future__ import annotations

import gc
import subprocess
import sys

from supportnode.cli import _process


def test_long_lived_pauses_the_collector_and_restores_it():
    assert gc.isenabled()
    frozen = gc.get_freeze_count()
    with _process.long_lived():
        assert not gc.isenabled()
    assert gc.isenabled()
    # main was not the process here (a test calls it): nothing frozen, nothing leaks
    assert gc.get_freeze_count() == frozen


def test_long_lived_leaves_a_disabled_collector_disabled():
    gc.disable()
    try:
        with _process.long_lived():
            pass
        assert not gc.isenabled()
    finally:
        gc.enable()


def test_the_command_process_freezes_what_it_loaded():
    code = (
        "import gc, sys; from supportnode.cli import _process\n"
        "_process.process_entry()\n"
        "with _process.long_lived(): import json\n"
        "sys.exit(0 if gc.isenabled() and gc.get_freeze_count() > 0 else 1)\n"
    )
    assert subprocess.run([sys.executable, "-c", code], timeout=60).returncode == 0


def test_end_returns_unless_the_command_left_nothing_to_finish():
    _process.end(0)  # not the command's process (a test calls main): returns
    code = (
        "import sys; from supportnode.cli import _process\n"
        "_process.process_entry()\n"
        "_process.end(5)\n"  # nothing_left not said: returns
        "print('buffered', end='')\n"
        "_process.nothing_left()\n"
        "_process.end(3)\n"
        "sys.exit(9)\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert (run.returncode, run.stdout) == (3, "buffered")  # flushed, then ended at once
