"""A plain-Python LZF decoder and greedy compressor: the reference the compiled kernel is
tested against (liblzf's stream format, see supportnode/kernels/lzf.py)."""

from __future__ import annotations


def decompress(src: bytes, size: int) -> bytes:
    """Decode byte by byte; ValueError on a corrupt stream or another size."""
    out = bytearray()
    ip = 0
    try:
        while ip < len(src):
            ctrl = src[ip]
            ip += 1
            if ctrl < 32:
                if ip + ctrl + 1 > len(src):
                    raise ValueError("literal run past the end of the data")
                out += src[ip : ip + ctrl + 1]
                ip += ctrl + 1
                continue
            length = ctrl >> 5
            if length == 7:
                length += src[ip]
                ip += 1
            ref = len(out) - (((ctrl & 31) << 8) | src[ip]) - 1
            ip += 1
            if ref < 0:
                raise ValueError("back-reference outside the output")
            for k in range(length + 2):
                out.append(out[ref + k])
    except IndexError as err:
        raise ValueError("compressed data ends inside a token") from err
    if len(out) != size:
        raise ValueError(f"LZF stream expands to {len(out)} bytes, not {size}")
    return bytes(out)


def compress(data: bytes) -> bytes:
    """Greedy LZF: back-references (3..264 bytes, distance <= 8192) to the last place each
    3-byte prefix was seen, literals otherwise; overlapping references included."""
    out = bytearray()
    literal = bytearray()
    last: dict[bytes, int] = {}

    def flush() -> None:
        for i in range(0, len(literal), 32):
            chunk = literal[i : i + 32]
            out.append(len(chunk) - 1)
            out.extend(chunk)
        literal.clear()

    ip = 0
    while ip < len(data):
        key = data[ip : ip + 3]
        ref = last.get(key) if len(key) == 3 else None
        last[key] = ip
        if ref is not None and ip - ref <= 8192:
            n = 0
            while n < 264 and ip + n < len(data) and data[ref + n] == data[ip + n]:
                n += 1
            flush()
            dist = ip - ref - 1
            if n - 2 < 7:
                out.append(((n - 2) << 5) | (dist >> 8))
            else:
                out += bytes([(7 << 5) | (dist >> 8), n - 2 - 7])
            out.append(dist & 255)
            ip += n
            continue
        literal.append(data[ip])
        ip += 1
    flush()
    return bytes(out)
