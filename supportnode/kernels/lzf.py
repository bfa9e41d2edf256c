"""LZF (liblzf) decompression in compiled code, as PCD ``binary_compressed`` needs it.

Stream format: a control byte ``c``; ``c < 32`` starts a literal run of ``c + 1`` bytes;
otherwise ``c >> 5`` is the back-reference length minus 2 (7: add the next byte) and
``((c & 31) << 8) | next byte`` is the distance minus 1. A back-reference may overlap its own
output (it then repeats the last ``distance`` bytes), so it is copied byte by byte.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from supportnode.kernels.runtime import warmer

# Return codes of the kernel (>= 0: bytes written)
_TRUNCATED = -1
_LITERAL_PAST_END = -2
_REF_OUTSIDE = -3

_MESSAGES = {
    _TRUNCATED: "compressed data ends inside a token",
    _LITERAL_PAST_END: "literal run past the end of the data",
    _REF_OUTSIDE: "back-reference outside the output",
}


@njit(cache=True, nogil=True)
def _decompress(src: np.ndarray, out: np.ndarray) -> int:
    n_in = src.size
    size = out.size
    # int64 throughout: numba types a variable once, and the stream's bytes are uint8
    ip = np.int64(0)
    op = np.int64(0)
    while ip < n_in:
        ctrl = np.int64(src[ip])
        ip += 1
        if ctrl < 32:
            n = ctrl + 1
            if ip + n > n_in or op + n > size:
                return _LITERAL_PAST_END
            out[op : op + n] = src[ip : ip + n]
            ip += n
            op += n
            continue
        length = ctrl >> 5
        if length == 7:
            if ip >= n_in:
                return _TRUNCATED
            length += np.int64(src[ip])
            ip += 1
        length += 2
        if ip >= n_in:
            return _TRUNCATED
        ref = op - (((ctrl & 31) << 8) | np.int64(src[ip])) - 1
        ip += 1
        if ref < 0 or op + length > size:
            return _REF_OUTSIDE
        for k in range(length):
            out[op + k] = out[ref + k]
        op += length
    return int(op)


def lzf_decompress(data: bytes | bytearray | memoryview | np.ndarray, size: int) -> np.ndarray:
    """Decompress an LZF stream that must expand to exactly ``size`` bytes.

    data: the compressed bytes. Returns (size,) uint8. Raises ValueError (naming what is
    wrong) on a corrupt stream or one that expands to another size.
    """
    if size < 0:
        raise ValueError(f"size must be >= 0, got {size}")
    src = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data
    src = np.ascontiguousarray(src, dtype=np.uint8).ravel()
    out = np.empty(int(size), dtype=np.uint8)
    n = _decompress(src, out)
    if n < 0:
        raise ValueError(_MESSAGES[n])
    if n != size:
        raise ValueError(f"LZF stream expands to {n} bytes, header says {size}")
    return out


@warmer
def _warm() -> None:
    # "aaaa": a literal 'a' then a back-reference of length 3 at distance 1
    lzf_decompress(bytes([0, 97, 1 << 5, 0]), 4)
