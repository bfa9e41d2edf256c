"""Drawing a :class:`~supportnode.render.source.Frame` as a matplotlib Figure. No files here.

The figure's layout (limits, legend, scale bar, title) is here; the views' geometry is in
`supportnode.render.projection`, the layers drawn on the axes in `supportnode.render.layers`.
Every view is an orthographic projection of the 3-D scene onto the picture plane (top, side and
oblique differ only in azimuth and elevation), drawn on ordinary 2-D axes: one code path for
points, outlines, boxes and discs, equal scale in x and y so the scale bar holds, and
``ax.transData`` maps projected metres to pixels exactly (tests rely on that).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from supportnode.errors import SupportNodeError
from supportnode.render.layers import (
    BOX_RGB,
    DISC_RGB,
    GREY_RGB,
    OFF_BOX_RGB,
    OTHER_RGB,
    OUTLINE_RGB,
    SURFACE_RGB,
    Labels,
    draw_discs,
    draw_objects,
    draw_points,
    draw_surfaces,
    legend_handles,
    point_colours,
)
from supportnode.render.projection import (
    COLOR_MODES,
    VIEWS,
    extent,
    fit_limits,
    nice_length,
    project,
    view_basis,
)
from supportnode.render.source import Frame

if TYPE_CHECKING:  # matplotlib is an optional extra: never imported at module level
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "BOX_RGB",
    "COLOR_MODES",
    "DISC_RGB",
    "GREY_RGB",
    "OFF_BOX_RGB",
    "OTHER_RGB",
    "OUTLINE_RGB",
    "SURFACE_RGB",
    "VIEWS",
    "draw_frame",
    "point_colours",
    "project",
    "view_basis",
]

# Figure layout in pixels, scaled with the font: room for title + legend above, ticks below/left.
_MARGIN = {"left": 7.0, "right": 1.5, "bottom": 4.5}  # in font heights


def _require_matplotlib() -> None:
    try:
        import matplotlib  # noqa: F401
    except ImportError as err:
        raise SupportNodeError("render needs matplotlib: pip install 'supportnode[viz]'") from err


def draw_frame(
    frame: Frame,
    *,
    view: str = "top",
    color: str = "class",
    max_points: int = 200_000,
    size: tuple[int, int] = (1600, 1200),
    dpi: float = 100,
    seed: int = 0,
) -> tuple[Figure, Axes]:
    """Draw one frame; returns (figure, axes). Pure: reads no files, changes no global state
    (no pyplot, no backend switch: the figure has its own Agg canvas).

    The figure is exactly ``size`` pixels at ``dpi`` (save it with the same dpi). Data
    coordinates of the axes are picture-plane metres and the limits are final on return, so
    ``ax.transData.transform(project(p, view))`` gives the display pixels (origin bottom left)
    of world points ``p``. At most ``max_points`` points are drawn (a random subset, seeded by
    ``seed``); outlines, boxes, discs and the counts in the legend come from the full result.
    Crowded object labels are left out (the footnote says how many).
    """
    _require_matplotlib()
    from matplotlib import patheffects

    basis = view_basis(view)
    colours = point_colours(frame, color)
    w_px, h_px = (int(v) for v in size)
    if w_px < 200 or h_px < 150 or not dpi > 0:
        raise SupportNodeError(f"picture size {w_px}x{h_px} at {dpi} dpi: need at least 200x150")
    if max_points < 1:
        raise SupportNodeError(f"max_points must be at least 1, got {max_points}")
    result = frame.result

    # Text size follows the picture so small and large ones stay legible; margins follow text.
    fs = 9.0 * float(np.clip(min(w_px, h_px) / 900.0, 0.7, 2.0))
    fig, ax, box = _figure_and_axes(frame, view, color, (w_px, h_px), dpi, fs)
    box_w, box_h = box[2] * w_px, box[3] * h_px

    lo, hi = extent(frame, basis)
    xlim, ylim = fit_limits(lo, hi, box_w, box_h)
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal", adjustable="datalim")  # equal by construction already; keep it so
    ax.set_autoscale_on(False)  # adding collections must not move the limits

    drawn = draw_points(ax, frame, colours, basis, view, max_points, seed, box_w * box_h, dpi)

    halo = [patheffects.withStroke(linewidth=max(2.0, fs / 3.0), foreground="white")]
    labels = Labels(ax, fs, dpi, halo)
    lw = max(1.0, fs / 6.0)
    draw_surfaces(ax, result, basis, labels, fs, lw)
    draw_objects(ax, result, basis, view, color, labels, fs, lw)
    draw_discs(ax, result, basis, lw)
    _texts(fig, ax, frame, view, box, drawn, labels.hidden, (xlim, ylim), fs, (w_px, h_px), dpi)
    return fig, ax


def _text_line(fs: float, dpi: float) -> float:
    """Height of one line of text at font size ``fs``, pixels."""
    return fs * dpi / 72.0 * 1.5


def _figure_and_axes(
    frame: Frame, view: str, color: str, size: tuple[int, int], dpi: float, fs: float
) -> tuple[Figure, Axes, list[float]]:
    """A figure of exactly ``size`` pixels with its legend on top, and the axes below it in
    ``box`` (left, bottom, width, height as fractions of the figure)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    w_px, h_px = size
    line = _text_line(fs, dpi)
    fig = Figure(figsize=(w_px / dpi, h_px / dpi), dpi=dpi, facecolor="white")
    FigureCanvasAgg(fig)  # attaches itself: savefig and canvas.draw work without pyplot
    left, bottom, right = 4.5 * line, 3.2 * line, 1.0 * line
    if view == "oblique":  # no tick labels
        left, bottom = 1.0 * line, 2.0 * line
    legend = _place_legend(fig, legend_handles(frame, color, fs), left, 1.7 * line, fs, w_px)
    top = 1.7 * line + legend.get_window_extent().height + 0.6 * line
    box = [left / w_px, bottom / h_px, 1 - (left + right) / w_px, 1 - (bottom + top) / h_px]
    if box[2] <= 0.1 or box[3] <= 0.1:
        raise SupportNodeError(f"picture size {w_px}x{h_px} is too small for its text")
    return fig, fig.add_axes((box[0], box[1], box[2], box[3])), box


def _texts(
    fig: Figure,
    ax: Axes,
    frame: Frame,
    view: str,
    box: list[float],
    drawn: int,
    hidden: int,
    limits: tuple[tuple[float, float], tuple[float, float]],
    fs: float,
    size: tuple[int, int],
    dpi: float,
) -> None:
    """Title, scale bar, axis labels and the footnote (notes, labels left out)."""
    w_px, h_px = size
    line = _text_line(fs, dpi)
    fig.text(
        box[0],
        1 - 0.6 * line / h_px,
        _title(frame, view, drawn, len(frame.points)),
        fontsize=fs * 1.2,
        va="top",
    )
    _scale_bar(ax, limits[0], limits[1], fs)
    _axes_labels(ax, view, fs)
    notes = list(frame.notes)
    if hidden:
        notes.append(f"{hidden} crowded object label{'s' if hidden > 1 else ''} left out")
    if notes:
        fig.text(
            1 - 0.3 * line / w_px, 0.3 * line / h_px, "; ".join(notes),
            ha="right", va="bottom", fontsize=fs * 0.85, color="0.3",
        )  # fmt: skip


def _place_legend(
    fig: Figure, handles: list[Any], left: float, top: float, fs: float, w_px: int
) -> Any:
    """The legend in as many columns as fit the picture's width (measured, not guessed), its
    top-left corner `left`, `top` pixels from the figure's top-left."""
    h_px = fig.get_size_inches()[1] * fig.dpi
    renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]  # an Agg canvas
    for ncol in range(len(handles), 0, -1):
        legend = fig.legend(
            handles=handles,
            loc="upper left",
            bbox_to_anchor=(left / w_px, 1 - top / h_px),
            ncol=ncol,
            fontsize=fs,
            frameon=False,
            handlelength=1.8,
            columnspacing=1.2,
            borderaxespad=0.0,
            borderpad=0.0,
        )
        if ncol == 1 or legend.get_window_extent(renderer).x1 <= w_px - 4:
            return legend
        legend.remove()
    raise AssertionError("unreachable")


def _scale_bar(ax: Axes, xlim: tuple[float, float], ylim: tuple[float, float], fs: float) -> None:
    """A 1-2-5 metre bar; picture-plane x is true length in every view (orthographic)."""
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    length = nice_length(xlim[1] - xlim[0])
    ax.add_artist(
        AnchoredSizeBar(
            ax.transData,
            length,
            f"{length:g} m" if length >= 1 else f"{length * 100:g} cm",
            loc="lower left",
            frameon=True,
            size_vertical=(ylim[1] - ylim[0]) * 0.006,
            color="black",
            fontproperties={"size": fs},
            pad=0.4,
            borderpad=0.6,
        )
    )


def _axes_labels(ax: Axes, view: str, fs: float) -> None:
    if view == "oblique":  # projected coordinates mean nothing to a reader: no ticks
        az, el = VIEWS[view]
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_xlabel(
            f"azimuth {az:g}°, elevation {el:g}°; far points paler; scale bar true across",
            fontsize=fs,
        )
        return
    ax.tick_params(labelsize=fs * 0.9)
    ax.set_xlabel("x (m)", fontsize=fs)
    ax.set_ylabel(
        "y (m)" if view == "top" else "z (m), seen from -y; far points paler", fontsize=fs
    )
    ax.grid(True, color="0.9", lw=0.6)
    ax.set_axisbelow(True)


def _title(frame: Frame, view: str, drawn: int, total: int) -> str:
    r = frame.result
    pts = f"{drawn:,} of {total:,} points drawn" if drawn < total else f"{total:,} points"
    return (
        f"{frame.name or 'result'}, {view} view: {len(r['surfaces'])} surfaces, "
        f"{len(r['objects'])} objects, {pts}"
    )
