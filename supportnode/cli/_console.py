"""What the commands print: progress while they work, tables when done.

On a terminal a job over a second long shows a rich progress bar (what, how many, elapsed,
ETA) on stderr; in logs and pipes it prints a plain line now and then instead (every 10 % or
5 s), and ``quiet`` silences both. Tables are rich tables, plain columns without borders so
that they read the same in a terminal, a log or ``grep``. rich is imported when something is
drawn with it (~20 ms of a command that takes well under a second).
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from rich.console import Console

__all__ = ["Interrupted", "Progress", "print_table", "progress"]

# Pipes and logs get wide tables rather than rich's 80 columns: nothing is cut.
_PIPE_WIDTH = 160
_PLAIN_EVERY_S = 5.0
# Jobs shorter than this print no progress lines (they are done before anyone waits), s.
_PLAIN_AFTER_S = 1.0
# In a pipe, a job with no line yet after this long prints one saying what it waits for.
_PLAIN_WAITING_S = 2.0


class Interrupted(KeyboardInterrupt):
    """Ctrl-C during a job, with what it leaves behind (``main`` prints it in one line)."""

    def __init__(self, detail: str) -> None:
        super().__init__(detail)
        self.detail = detail


def make_console(**options: Any) -> Console:
    """A rich ``Console(**options)``."""
    from rich.console import Console

    return Console(**options)


def stdout_console() -> Console:
    return make_console(width=None if sys.stdout.isatty() else _PIPE_WIDTH, highlight=False)


def print_table(
    columns: Sequence[str],
    rows: Sequence[Sequence[Any]],
    title: str | None = None,
    left: int = 1,
) -> None:
    """Print a table on stdout: the first ``left`` columns left-aligned, the others right."""
    cells = [[str(v) for v in row] for row in rows]
    plain = None if sys.stdout.isatty() else plain_table(columns, cells, title, left)
    if plain is not None:
        sys.stdout.write(plain)
        return
    from rich.table import Table

    table = Table(title=title, box=None, pad_edge=False, title_justify="left", show_edge=False)
    for i, name in enumerate(columns):
        table.add_column(name, justify="left" if i < left else "right", no_wrap=True)
    for row in cells:
        table.add_row(*row)
    stdout_console().print(table)


def plain_table(
    columns: Sequence[str], cells: Sequence[Sequence[str]], title: str | None, left: int
) -> str | None:
    """The text rich prints for `print_table` into a pipe, without importing rich (~15 ms of a
    short command): columns two spaces apart, each as wide as its widest cell. Only for what
    this reproduces exactly (tested against rich): no title, the last column right-aligned,
    printable ASCII without rich's markup or emoji codes ("[", ":"), cells without outer
    spaces, no empty column, within _PIPE_WIDTH; None otherwise."""
    table = [list(columns), *(list(row) for row in cells)]
    if title is not None or not 0 <= left < len(columns):
        return None
    if any(len(row) != len(columns) for row in table):
        return None
    text = "".join(c for row in table for c in row)
    if not (text.isascii() and text.isprintable()) or "[" in text or ":" in text:
        return None
    if any(c != c.strip() for row in table for c in row):  # rich trims cells in places
        return None
    widths = [max(len(row[i]) for row in table) for i in range(len(columns))]
    if min(widths) == 0 or sum(widths) + 2 * (len(widths) - 1) > _PIPE_WIDTH:
        return None
    lines = [
        "  ".join(
            c.ljust(w) if i < left else c.rjust(w)
            for i, (c, w) in enumerate(zip(row, widths, strict=True))
        )
        for row in table
    ]
    return "\n".join(lines) + "\n"


class Progress:
    """Counts work done: ``advance(n)``, ``total`` may be None (unknown)."""

    def __init__(self, what: str, total: float | None, unit: str, quiet: bool) -> None:
        self.what, self.total, self.unit = what, total, unit
        self.done = 0.0
        self._t0 = time.monotonic()
        self._last_line = self._t0
        self._last_share = 0.0
        self._bar: Any = None
        self._task: Any = None
        self._note: str | None = None
        self._lock = threading.Lock()  # the bar starts in a timer's thread
        self._timer: threading.Timer | None = None
        if quiet:
            self._mode = "quiet"
        elif sys.stderr.isatty():
            self._mode = "bar"
            # Jobs done within _PLAIN_AFTER_S draw no bar (nor import rich.progress).
            self._timer = threading.Timer(_PLAIN_AFTER_S, self._start_bar)
            self._timer.daemon = True
            self._timer.start()
        else:
            self._mode = "plain"
            # A long first stage (a fresh install's kernels compiling) says what it waits for
            # once, rather than nothing until it ends.
            self._timer = threading.Timer(_PLAIN_WAITING_S, self._plain_waiting)
            self._timer.daemon = True
            self._timer.start()

    def _start_bar(self) -> None:
        from rich import progress as rp

        with self._lock:
            if self._mode != "bar":  # closed meanwhile
                return
            self._bar = self._new_bar(rp)
            self._bar.start()
            self._task = self._bar.add_task(
                self._note or self.what, total=self.total, completed=self.done
            )
            self._bar.tasks[-1].start_time = self._t0  # elapsed and ETA from the job's start

    def _new_bar(self, rp: Any) -> Any:
        return rp.Progress(
            rp.TextColumn("{task.description}"),
            rp.BarColumn(),
            rp.MofNCompleteColumn(),
            rp.TextColumn(self.unit),
            rp.TimeElapsedColumn(),
            rp.TimeRemainingColumn(),
            console=make_console(stderr=True),
            transient=True,
        )

    def advance(self, n: float = 1.0, note: str | None = None) -> None:
        with self._lock:
            self.done += n
            self._note = note
            if self._mode == "bar" and self._bar is not None:
                self._bar.update(self._task, advance=n, description=note or self.what)
            elif self._mode == "plain":
                self._plain(note)

    def _plain_waiting(self) -> None:
        """The timer's line in a pipe: the job and its note, unless a line came already."""
        with self._lock:
            if self._mode == "plain" and self._last_line == self._t0:
                self._plain(self._note, force=True)

    def _plain(self, note: str | None, force: bool = False) -> None:
        now = time.monotonic()
        share = self.done / self.total if self.total else 0.0
        if now - self._t0 < _PLAIN_AFTER_S and not force:
            return
        if now - self._last_line < _PLAIN_EVERY_S and share - self._last_share < 0.1 and not force:
            return
        self._last_line, self._last_share = now, share
        elapsed = now - self._t0
        of = f"/{self.total:.0f}" if self.total else ""
        eta = f", about {elapsed / share - elapsed:.0f} s left" if 0 < share < 1 else ""
        extra = f" ({note})" if note else ""
        print(
            f"{self.what}: {self.done:.0f}{of} {self.unit}, {elapsed:.0f} s{eta}{extra}",
            file=sys.stderr,
            flush=True,
        )

    def close(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
        with self._lock:
            self._mode = "closed" if self._mode == "bar" else self._mode
            if self._bar is not None:
                self._bar.stop()
                self._bar = None


@contextmanager
def progress(
    what: str, total: float | None = None, unit: str = "", quiet: bool = False
) -> Iterator[Progress]:
    """A `Progress` for a job; the bar is removed when the job ends (also on Ctrl-C)."""
    p = Progress(what, total, unit, quiet)
    try:
        yield p
    finally:
        p.close()
