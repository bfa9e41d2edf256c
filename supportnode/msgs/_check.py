"""`Check`: the validation steps every decoder (and encoder) runs, each failure one
`ProtocolError` naming the topic and the problem."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any, NoReturn

import numpy as np

from supportnode.errors import ProtocolError

__all__ = ["INT64_MAX", "INT64_MIN", "Check", "dtype_choices", "kind_of", "short"]

INT64_MIN, INT64_MAX = -(1 << 63), (1 << 63) - 1


class Check:
    """Raises one-line ProtocolErrors that name the topic; type checks of header values."""

    def __init__(self, topic: str, prefix: str = "") -> None:
        self.topic = topic
        self.prefix = prefix  # "cannot encode: " when checking a message before sending it

    def fail(self, problem: str, reason: str = "malformed") -> NoReturn:
        """Raise the ProtocolError; ``reason``: what a receiver counts it under."""
        raise ProtocolError(f"topic {self.topic!r}: {self.prefix}{problem}", reason)

    def key(self, m: Mapping[str, Any], key: str, path: str = "header") -> Any:
        """``m[key]``, or a failure naming the missing key."""
        if key not in m:
            self.fail(f"{path} has no key '{key}'")
        return m[key]

    def as_map(self, v: Any, what: str) -> dict[str, Any]:
        if not isinstance(v, dict):
            self.fail(f"{what} must be a map, got {kind_of(v)}")
        for k in v:
            if not isinstance(k, str):
                self.fail(f"{what} has a non-string key {short(k)}")
        return v

    def as_str(self, v: Any, what: str) -> str:
        if not isinstance(v, str):
            self.fail(f"{what} must be a string, got {kind_of(v)}")
        return v

    def as_int(self, v: Any, what: str, lo: int = INT64_MIN, hi: int = INT64_MAX) -> int:
        if isinstance(v, bool) or not isinstance(v, int):
            self.fail(f"{what} must be an integer, got {kind_of(v)}")
        if not lo <= v <= hi:
            self.fail(f"{what} = {v} is out of range [{lo}, {hi}]")
        return v

    def as_float(self, v: Any, what: str, lo: float = -math.inf) -> float:
        """A finite number (msgpack float or int) >= lo."""
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.fail(f"{what} must be a number, got {kind_of(v)}")
        try:
            x = float(v)
        except OverflowError:  # a msgpack uint64 cannot overflow, but be safe
            self.fail(f"{what} is out of range")
        if not math.isfinite(x):
            self.fail(f"{what} is {x} (must be finite)", "nonfinite")
        if x < lo:
            self.fail(f"{what} = {x} must be >= {lo}")
        return x

    def as_vector(self, v: Any, what: str, n: int) -> np.ndarray:
        """A list of ``n`` finite numbers -> (n,) float64."""
        if not isinstance(v, list) or len(v) != n:
            got = f"{len(v)} items" if isinstance(v, list) else kind_of(v)
            self.fail(f"{what} must be a list of {n} numbers, got {got}")
        return np.array([self.as_float(x, f"{what}[{i}]") for i, x in enumerate(v)])

    def unit_quaternion(self, v: Any, what: str) -> np.ndarray:
        q = self.as_vector(v, what, 4)
        with np.errstate(over="ignore"):  # 1e308 components: norm inf, rejected below
            norm = float(np.linalg.norm(q))
        if abs(norm - 1.0) > 1e-3:
            self.fail(f"{what} has norm {norm:.6g} (must be a unit quaternion x, y, z, w)")
        return q

    def array(
        self,
        buffers: Mapping[str, np.ndarray],
        name: str,
        dtypes: frozenset[str],
        tail: tuple[int, ...] = (),
    ) -> np.ndarray:
        """Buffer ``name`` with a dtype from ``dtypes`` and shape (n, *tail)."""
        if name not in buffers:
            self.fail(f"missing buffer '{name}'")
        a = buffers[name]
        if a.dtype.str not in dtypes:
            self.fail(
                f"buffer '{name}' has dtype '{a.dtype.str}', expected {dtype_choices(dtypes)}"
            )
        if a.ndim != 1 + len(tail) or a.shape[1:] != tail:
            want = "(n" + "".join(f", {t}" for t in tail) + (",)" if not tail else ")")
            self.fail(f"buffer '{name}' has shape {a.shape}, expected {want}")
        return a

    def length(self, a: np.ndarray, name: str, n: int, of: str) -> None:
        if len(a) != n:
            self.fail(f"buffer '{name}' has {len(a)} rows, expected {n} ({of})")

    def finite(self, a: np.ndarray, name: str) -> None:
        if a.dtype.kind == "f":
            bad = int(np.count_nonzero(~np.isfinite(a)))
            if bad:
                self.fail(f"{bad} NaN/Inf values in {name}", "nonfinite")

    def offsets(self, a: np.ndarray, name: str, items: int, total: int) -> None:
        """CSR offsets: (items + 1,) from 0 to ``total``, non-decreasing."""
        self.length(a, name, items + 1, "one more than the items it splits")
        # Bounds first: differences of arbitrary int64 values could wrap around.
        if a[0] != 0 or a[-1] != total or bool(np.any(a < 0)) or bool(np.any(a > total)):
            self.fail(f"buffer '{name}' must run from 0 to {total}")
        if bool(np.any(np.diff(a) < 0)):
            self.fail(f"buffer '{name}' must be non-decreasing")


def kind_of(v: Any) -> str:
    """A value's type as msgpack calls it (``nil`` for None)."""
    return "nil" if v is None else type(v).__name__


def short(v: Any) -> str:
    """repr of ``v``, cut to 40 characters for error lines."""
    r = repr(v)
    return r if len(r) <= 40 else r[:37] + "..."


def dtype_choices(dtypes: frozenset[str]) -> str:
    """``'<f4' or '<f8'``: the allowed dtype strings, for error lines."""
    return " or ".join(f"'{d}'" for d in sorted(dtypes))
