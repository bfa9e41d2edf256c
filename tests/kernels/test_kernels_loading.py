"""Kernels loaded from numba's cache without its compile set-up: same results, compiles intact."""

import subprocess
import sys
import textwrap
from pathlib import Path

from supportnode.kernels import loading

# A fresh process: the switch is process-wide, and whether numba's registries were loaded is
# only visible in a process that has not compiled anything yet.
_LOAD_THEN_COMPILE = textwrap.dedent(
    """
    import sys
    import numpy as np
    from supportnode.kernels import loading, runtime, rects
    import llvmlite.binding.ffi as ffi

    applied = loading.load_lightly()
    assert loading.load_lightly() == applied  # idempotent
    runtime.warm()  # loads rects' kernels from the cache
    print("applied", applied)
    print("registries", "numba.typed.typedset" in sys.modules)
    print("lock_events", [a.__module__ for a, _ in ffi.lib._lock._cblist])
    z = np.array([0.0, 1.0, 0.0])
    best, ext = rects.min_area_boxes(z, np.array([0.0, 0.0, 1.0]), np.array([0, 3]), z, z + 1, z)
    print("kernel", best.tolist(), ext.tolist())

    from numba import njit  # a compile after light loads refreshes numba itself

    @njit
    def _sorted(a):
        return np.sort(a)

    print("compiled", _sorted(np.array([3.0, 1.0, 2.0])).tolist())
    print("registries", "numba.typed.typedset" in sys.modules)

    # A loaded library's functions are found, a name it lacks is 0, and a new kernel that
    # calls a loaded one links it (its bitcode parsed then).
    library = next(iter(rects._boxes.overloads.values())).library
    print("lazy", "_supportnode_bitcode" in library.__dict__)
    print("missing", library.get_pointer_to_function("no_such_function"))

    @njit
    def _via(x, y, starts, angles, cos, sin):
        return rects._boxes(x, y, starts, angles, cos, sin)

    best, ext = _via(z, np.array([0.0, 0.0, 1.0]), np.array([0, 3]), z, z + 1, z)
    print("linked", best.tolist(), ext.tolist())
    print("lazy", "_supportnode_bitcode" in library.__dict__)
    """
)


def _run(code: str) -> dict[str, list[str]]:
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    out: dict[str, list[str]] = {}
    for line in done.stdout.splitlines():
        key, _, value = line.partition(" ")
        out.setdefault(key, []).append(value)
    return out


def test_light_loads_skip_the_registries_and_compiles_still_load_them():
    out = _run(_LOAD_THEN_COMPILE)
    assert out["applied"] == ["True"], "numba's Cache.load_overload changed: re-check loading.py"
    assert out["registries"] == ["False", "True"]  # skipped by the loads, loaded by the compile
    assert out["lock_events"] == ["[]"]
    assert out["compiled"] == ["[1.0, 2.0, 3.0]"]
    assert out["lazy"] == ["True", "False"]  # parsed once a compile linked it
    assert out["missing"] == ["0"]
    assert out["linked"] == out["kernel"]


def test_a_kernel_loaded_lightly_gives_what_it_gives_after_a_full_load():
    out = _run(_LOAD_THEN_COMPILE)
    full = _run(_LOAD_THEN_COMPILE.replace("loading.load_lightly()", "False"))
    assert out["kernel"] == full["kernel"]
    assert full["registries"] == ["True", "True"]


def test_another_numba_is_left_as_it_is(monkeypatch):
    from numba.core import caching

    def load_overload(self, sig, target_context):  # not the refresh-then-load known
        return None

    monkeypatch.setattr(caching.Cache, "load_overload", load_overload)
    monkeypatch.setattr(loading, "_applied", None)
    monkeypatch.setattr(loading, "_drop_lock_events", lambda: None)
    assert loading.load_lightly() is False
    assert caching.Cache.load_overload is load_overload


def test_supportnode_detect_loads_its_kernels_lightly(tmp_path):
    """supportnode's own processes switch it on (the node's warm-up too, `rehearsal`); a
    detect then imports neither numba's registries nor scipy.spatial (~0.3 s of a fresh run)."""
    cloud = Path(__file__).resolve().parents[2] / "sim_scans" / "table_chairs_sampled.ply"
    code = (
        "import sys; from supportnode.cli import _main; "
        f"code = _main(['detect', {str(cloud)!r}, '--out', {str(tmp_path / 'out')!r}, '--quiet']); "
        "print('exit', code); "
        "print('imported', [m for m in ('numba.typed.typedset', 'numba.np.arraymath', "
        "'scipy.spatial', 'scipy.linalg') if m in sys.modules])"
    )
    _run(code)  # compiles what the cache lacks (a compile loads the registries)
    out = _run(code)
    assert out["exit"] == ["0"]
    assert out["imported"] == ["[]"]
    assert (tmp_path / "out" / "result.json").is_file()


def test_no_kernel_needs_numba_np_arraymath_to_load():
    """A cached kernel that called numba's array math (ndarray.any, np.flatnonzero, ...)
    imports numba.np.arraymath as it loads, and with it scipy's BLAS (~80 ms)."""
    code = textwrap.dedent(
        """
        import sys
        from supportnode.kernels import loading, precompile, runtime
        loading.load_lightly()
        runtime.warm(precompile.kernel_modules())
        print("imported", [m for m in ("numba.np.arraymath", "scipy.linalg") if m in sys.modules])
        """
    )
    _run(code)  # compiles what the cache lacks
    assert _run(code)["imported"] == ["[]"]
