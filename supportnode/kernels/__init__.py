"""Compiled loops: numba ``@njit(cache=True, nogil=True)`` kernels, arrays in, arrays out.

Floor 0 of the package: nothing here imports from the rest of supportnode, and nothing above
sees a numba type. Each module holds the kernels of one job (voxel store, region growing,
connected components, ray clearing, rasters, LZF) behind plain typed Python functions that
check their inputs (shape, dtype, finite values) before the compiled code runs.

Conventions:
- ``@njit(cache=True, nogil=True)`` always: the compile cost is paid once per machine (numba
  writes the cache beside the source, or under ``NUMBA_CACHE_DIR`` / the user cache when that
  is read-only), and the node's other thread runs Python while a kernel runs (the receiving
  side merges the next scan while the detecting side labels this one).
- A module that adds kernels registers a small warm-up with :func:`runtime.warmer`; the node
  calls :func:`runtime.warm` before it subscribes, then rehearses one detection
  (`supportnode.node.rehearsal`), so its first scan is not slow. On an empty cache the first
  `runtime.warm` compiles every kernel module in child processes first (`precompile`).
- A kernel that replaces numpy code gives the same bits: the same operations in the same order
  (numpy's pairwise sums reproduced; its arccos and cos kept, its SIMD versions rounding
  differently from the C library's), and the numpy version stays as the tests' reference.
- No numba array math from ``numba.np.arraymath`` in a kernel (``ndarray.any``,
  ``np.flatnonzero``, ...: write the loop): loading such a kernel from the cache imports that
  module, and scipy's BLAS with it, ~80 ms of a fresh ``supportnode detect`` (tested in
  ``tests/kernels/test_kernels_loading.py``; `loading` says what else a load skips).
- ``parallel=True`` / ``prange`` only where measured to pay on two cores; the threading layer
  and thread count are set once by :func:`runtime.configure` (``node.threads``).
- This package's ``__init__`` imports nothing: ``import supportnode.client`` must not load numba.
"""
