"""LZF (liblzf) decompression and a literal-only compressor, as used by PCD ``binary_compressed``.

The C package ``lzf`` (PyPI ``python-lzf``) is used when importable; otherwise a pure-Python
decoder runs. Stream format: a control byte ``c``; ``c < 32`` starts a literal run of ``c + 1``
bytes; otherwise ``c >> 5`` is the back-reference length minus 2 (7 means "add the next byte"),
and ``((c & 31) << 8) | next byte`` is the distance minus 1.
"""

from __future__ import annotations

try:  # optional C accelerator
    import lzf as _clzf  # type: ignore[import-not-found]
except ImportError:  # pragma: no cover - depends on the environment
    _clzf = None


class LZFError(ValueError):
    """The compressed stream is corrupt or does not decompress to the expected size."""


def decompress(data: bytes, size: int) -> bytes:
    """Decompress an LZF stream that must expand to exactly ``size`` bytes."""
    if _clzf is not None:
        try:
            out = _clzf.decompress(bytes(data), size)
        except Exception as err:  # the C module raises assorted errors on corrupt input
            raise LZFError(f"corrupt LZF stream ({err})") from err
        if out is None or len(out) != size:
            raise LZFError(f"LZF stream does not expand to {size} bytes")
        return bytes(out)
    return _decompress_py(bytes(data), size)


def _decompress_py(src: bytes, size: int) -> bytes:
    out = bytearray(size)
    n_in = len(src)
    ip = 0
    op = 0
    try:
        while ip < n_in:
            ctrl = src[ip]
            ip += 1
            if ctrl < 32:
                # literal run: one slice copy instead of a byte loop
                n = ctrl + 1
                end = ip + n
                if end > n_in or op + n > size:
                    raise LZFError("literal run past the end of the data")
                out[op : op + n] = src[ip:end]
                ip = end
                op += n
                continue
            length = ctrl >> 5
            if length == 7:
                length += src[ip]
                ip += 1
            length += 2
            ref = op - (((ctrl & 31) << 8) | src[ip]) - 1
            ip += 1
            if ref < 0 or op + length > size:
                raise LZFError("back-reference outside the output")
            dist = op - ref
            if dist >= length:
                out[op : op + length] = out[ref : ref + length]
            elif dist == 1:
                # run of one repeated byte (very common: NaN padding, flat colours)
                out[op : op + length] = out[ref : ref + 1] * length
            else:
                # overlapping copy repeats the last `dist` bytes
                pattern = out[ref:op]
                out[op : op + length] = (pattern * (length // dist + 1))[:length]
            op += length
    except IndexError as err:
        raise LZFError("compressed data ends inside a token") from err
    if op != size:
        raise LZFError(f"LZF stream expands to {op} bytes, header says {size}")
    return bytes(out)


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
        import numpy as np

        blocks = np.empty((full, 33), dtype=np.uint8)
        blocks[:, 0] = 31
        blocks[:, 1:] = np.frombuffer(data, dtype=np.uint8, count=full * 32).reshape(full, 32)
        out[: full * 33] = blocks.tobytes()
    if rest:
        out[full * 33] = rest - 1
        out[full * 33 + 1 :] = data[full * 32 :]
    return bytes(out)
