"""Pictures of detection results: `supportnode render` and `supportnode detect --render`.

Three layers, so other sources (a recording, the node) can reuse the drawing:
- :mod:`supportnode.render.source`: a :class:`Frame` (points, labels, parsed result.json) from a
  detect output folder;
- :mod:`supportnode.render.draw`: :func:`draw_frame`, a Frame -> (Figure, Axes), no files
  (its parts: :mod:`~supportnode.render.projection`, the views' geometry, and
  :mod:`~supportnode.render.layers`, what is drawn on the axes);
- here: :func:`render_frame` and :func:`render_result`, which write PNGs.

matplotlib is an optional extra (``supportnode[viz]``); it is imported only when drawing.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

from supportnode.errors import SupportNodeError
from supportnode.render.draw import COLOR_MODES, VIEWS, draw_frame, project
from supportnode.render.source import Frame, load_result, load_result_dir

if TYPE_CHECKING:  # matplotlib is an optional extra: never imported at module level
    from matplotlib.figure import Figure

__all__ = [
    "COLOR_MODES",
    "VIEWS",
    "Frame",
    "draw_frame",
    "load_result",
    "load_result_dir",
    "project",
    "render_frame",
    "render_result",
    "write_png",
]


def render_frame(
    frame: Frame,
    out_png: str | os.PathLike[str],
    *,
    view: str = "top",
    color: str = "class",
    max_points: int = 200_000,
    size: tuple[int, int] = (1600, 1200),
    dpi: float = 100,
    palette: bool = True,
) -> Path:
    """Draw `frame` (see :func:`draw_frame`) and write it as a PNG of exactly `size` pixels
    (palette: 256-colour PNG, about a third of the bytes; see :func:`write_png`)."""
    out = Path(out_png)
    if out.suffix.lower() != ".png":
        raise SupportNodeError(f"{out}: the picture is written as PNG; name it *.png")
    fig, _ = draw_frame(frame, view=view, color=color, max_points=max_points, size=size, dpi=dpi)
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        write_png(fig, out, palette=palette)
    except OSError as err:
        raise SupportNodeError(f"{out}: cannot write ({err.strerror or err})") from err
    return out


def write_png(fig: Figure, out: Path, *, palette: bool = True) -> None:
    """Write a figure at its own size and dpi (no bbox_inches="tight": that would change the
    pixel size the caller asked for).

    palette: store 256 colours with a palette instead of RGBA. Thousands of anti-aliased box
    edges over scattered points compress badly (a kitchen's oblique view: 650 KB RGBA, 210 KB
    palette); the picture has few colours that matter, and the octree quantiser keeps them
    (mean error about 1/255, no dithering). Pillow comes with matplotlib.
    """
    if not palette:
        fig.savefig(out, dpi=fig.dpi, format="png", facecolor="white")
        return
    import numpy as np
    from PIL import Image

    fig.canvas.draw()
    rgb = np.asarray(fig.canvas.buffer_rgba())[..., :3]  # type: ignore[attr-defined]  # Agg
    # method 2 = fast octree, dither 0 = none; plain ints so Pillow < 9.1 (no enums) works too
    img = Image.fromarray(np.ascontiguousarray(rgb)).quantize(256, method=2, dither=0)  # type: ignore[arg-type]
    img.save(out, format="png", dpi=(fig.dpi, fig.dpi))


def render_result(
    result_dir: str | os.PathLike[str],
    out_png: str | os.PathLike[str],
    view: str = "top",
    color: str = "class",
    max_points: int = 200_000,
    size: tuple[int, int] = (1600, 1200),
    dpi: float = 100,
) -> Path:
    """Draw the output folder of `supportnode detect` as a PNG; returns the path written.

    Raises SupportNodeError (one line) on a missing or corrupt folder, a bad option, or when
    matplotlib is not installed.
    """
    from supportnode.render.draw import _require_matplotlib

    _require_matplotlib()  # before reading a large cloud only to fail afterwards
    frame = load_result_dir(result_dir)
    return render_frame(
        frame, out_png, view=view, color=color, max_points=max_points, size=size, dpi=dpi
    )
