"""The kernels' runtime: a thread-safe threading layer, a bounded thread count, warm-up."""

import os
import subprocess
import sys
import textwrap

from supportnode.kernels import runtime


def test_configure_bounds_the_thread_count():
    import numba

    runtime.configure(threads=1)
    assert numba.get_num_threads() == 1
    runtime.configure(threads=10_000)
    assert numba.get_num_threads() == numba.config.NUMBA_NUM_THREADS


def test_warm_runs_every_registered_warmer():
    ran = []
    fn = runtime.warmer(lambda: ran.append(1))
    try:
        assert runtime.warm() >= 0.0
        assert ran == [1]
    finally:
        runtime._WARMERS.remove(fn)


def test_two_threads_in_parallel_kernels_do_not_abort_even_with_workqueue_asked():
    """numba's workqueue layer aborts the process when two threads enter parallel kernels;
    configure() asks for a thread-safe layer, which the environment variable cannot undo."""
    code = textwrap.dedent(
        """
        import threading
        import numpy as np
        from numba import njit, prange
        from supportnode.kernels import runtime

        runtime.configure(threads=2)

        @njit(parallel=True)
        def total(a):
            s = 0.0
            for i in prange(a.size):
                s += a[i]
            return s

        a = np.ones(200_000)
        out = []
        def work():
            for _ in range(200):
                out.append(total(a))
        ts = [threading.Thread(target=work) for _ in range(2)]
        [t.start() for t in ts]
        [t.join() for t in ts]
        assert out == [200_000.0] * 400, out[:3]
        print(runtime.configure())
        """
    )
    env = {**os.environ, "NUMBA_THREADING_LAYER": "workqueue"}
    proc = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=240, env=env
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.strip() in {"omp", "tbb"}


def test_keep_freed_memory_takes_on_glibc_and_is_a_no_op_elsewhere():
    """Fixed allocator thresholds (a scan's arrays reuse the last scan's pages); False where
    there is no glibc mallopt, never an error."""
    import platform

    took = runtime.keep_freed_memory()
    if sys.platform.startswith("linux") and platform.libc_ver()[0] == "glibc":
        assert took
    else:
        assert took is False


def test_the_thread_budget_reaches_a_worker_thread_that_applies_it():
    """numba's thread count is per thread: configure() sets its caller's only, and a worker
    (the node's detecting thread) takes the same budget with apply_threads()."""
    import threading

    import numba

    seen = {}

    def work():
        runtime.apply_threads()
        seen["threads"] = numba.get_num_threads()

    runtime.configure(threads=1)
    try:
        worker = threading.Thread(target=work)
        worker.start()
        worker.join()
    finally:
        runtime.configure(threads=numba.config.NUMBA_NUM_THREADS)
    assert seen["threads"] == 1


def test_the_nodes_detecting_thread_applies_the_thread_budget(monkeypatch):
    import threading

    from supportnode.node.detector import Detector
    from supportnode.node.mailbox import Mailbox

    calls = []
    monkeypatch.setattr(runtime, "apply_threads", lambda: calls.append(1))
    stop = threading.Event()
    stop.set()  # the loop ends at once, after its set-up
    Detector(None, Mailbox(), None, None, None, 0.01).run(stop)  # only the loop runs
    assert calls == [1]
