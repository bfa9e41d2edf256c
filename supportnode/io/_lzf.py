"""LZF (liblzf) streams as PCD ``binary_compressed`` stores them: decompression (a compiled
kernel, `supportnode.kernels.lzf`) and a literal-only compressor for the writer."""

from __future__ import annotations

import numpy as np


class LZFError(ValueError):
    """The compressed stream is corrupt or does not decompress to the expected size."""


def decompress(data: bytes | memoryview, size: int) -> np.ndarray:
    """Decompress an LZF stream that must expand to exactly ``size`` bytes: (size,) uint8."""
    from supportnode.kernels.lzf import lzf_decompress

    try:
        return lzf_decompress(data, size)
    except ValueError as err:
        raise LZFError(str(err)) from err


def compress_literal(data: bytes) -> bytes:
    """Encode ``data`` as a valid LZF stream made of literal runs only (no compression).

    Every decoder accepts it; the output is ``len(data) * 33 / 32`` bytes, rounded up.
    """
    data = bytes(data)
    n = len(data)
    if n == 0:
        return b""
    full, rest = divmod(n, 32)
    out = bytearray(full * 33 + (rest + 1 if rest else 0))
    if full:
        # vectorised layout: every 33-byte block is the control byte 31 and 32 data bytes
        blocks = np.empty((full, 33), dtype=np.uint8)
        blocks[:, 0] = 31
        blocks[:, 1:] = np.frombuffer(data, dtype=np.uint8, count=full * 32).reshape(full, 32)
        out[: full * 33] = blocks.tobytes()
    if rest:
        out[full * 33] = rest - 1
        out[full * 33 + 1 :] = data[full * 32 :]
    return bytes(out)
