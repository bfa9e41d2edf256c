"""Drawing a :class:`~supportnode.render.source.Frame` as a matplotlib Figure. No files here.

Every view is an orthographic projection of the 3-D scene onto the picture plane (top, side and
oblique differ only in azimuth and elevation), drawn on ordinary 2-D axes: one code path for
points, outlines, boxes and discs, equal scale in x and y so the scale bar holds, and
``ax.transData`` maps projected metres to pixels exactly (tests rely on that).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from supportnode.errors import SupportNodeError
from supportnode.render.source import Frame

if TYPE_CHECKING:  # matplotlib is an optional extra: never imported at module level
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

# (azimuth, elevation) in degrees of the direction the camera looks from, as in mplot3d.
VIEWS: dict[str, tuple[float, float]] = {
    "top": (-90.0, 90.0),  # looking down; x right, y up
    "side": (-90.0, 0.0),  # from -y; x right, z up
    "oblique": (-60.0, 30.0),  # front right, 30 degrees above the horizon
}
COLOR_MODES = ("class", "id")

# The report's colours, slightly softened so labels stay readable on top of them.
SURFACE_RGB = (0.90, 0.10, 0.10)
OTHER_RGB = (0.15, 0.70, 0.15)
GREY_RGB = (0.62, 0.62, 0.62)
# Points beyond these percentiles (each end, each picture axis) do not set the picture's extent.
_ROBUST_PERCENT = 2.0  # --color id: points on neither a surface nor an object
OUTLINE_RGB = (0.0, 0.0, 0.0)
BOX_RGB = (0.10, 0.25, 1.0)
OFF_BOX_RGB = (0.35, 0.35, 0.35)  # objects standing on no surface (walls, clutter)
DISC_RGB = (0.95, 0.0, 0.95)

# Figure layout in pixels, scaled with the font: room for title + legend above, ticks below/left.
_MARGIN = {"left": 7.0, "right": 1.5, "bottom": 4.5}  # in font heights
_DISC_VERTICES = 96


def _require_matplotlib() -> None:
    try:
        import matplotlib  # noqa: F401
    except ImportError as err:
        raise SupportNodeError("render needs matplotlib: pip install 'supportnode[viz]'") from err


def view_basis(view: str) -> np.ndarray:
    """(3, 3) rows: picture x, picture y and depth (towards the camera) in world coordinates."""
    if view not in VIEWS:
        raise SupportNodeError(f"unknown view {view!r} (expected {', '.join(VIEWS)})")
    az, el = (math.radians(v) for v in VIEWS[view])
    towards = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
    right = np.array([-math.sin(az), math.cos(az), 0.0])
    up = np.cross(towards, right)
    return np.round(np.vstack([right, up, towards]), 12)  # exact 0/1 for top and side


def project(points: np.ndarray, view: str) -> np.ndarray:
    """(N, 3) world metres -> (N, 2) picture-plane metres in `view` (what ax.transData takes)."""
    return np.asarray(points, dtype=np.float64).reshape(-1, 3) @ view_basis(view)[:2].T


def _palette(n: int, name: str) -> np.ndarray:
    from matplotlib import colormaps

    cmap = colormaps[name]
    return np.array([cmap(i % cmap.N)[:3] for i in range(max(n, 1))])


def point_colours(frame: Frame, color: str) -> np.ndarray:
    """(N, 3) RGB in [0, 1] for every point of the frame."""
    if color not in COLOR_MODES:
        raise SupportNodeError(f"unknown colour mode {color!r} (expected {', '.join(COLOR_MODES)})")
    surf = frame.surface
    on = surf >= 0
    if color == "class":
        return np.where(on[:, None], SURFACE_RGB, OTHER_RGB)
    out = np.tile(np.asarray(GREY_RGB), (len(surf), 1))
    out[on] = _palette(10, "tab10")[surf[on] % 10]
    if frame.object is not None:
        obj_on = (frame.object >= 0) & ~on
        out[obj_on] = _palette(20, "tab20")[frame.object[obj_on] % 20]
    return out


def _obb_corners(o: dict) -> np.ndarray:
    """(8, 3) corners of an object's yaw-only oriented box: bottom four CCW, then top four."""
    c = np.asarray(o["obb_center"], dtype=np.float64)
    half = np.asarray(o["obb_size"], dtype=np.float64) / 2.0
    yaw = float(o["obb_yaw"])
    ca, sa = math.cos(yaw), math.sin(yaw)
    local = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], dtype=np.float64) * half[:2]
    xy = local @ np.array([[ca, sa], [-sa, ca]]) + c[:2]
    bottom = np.c_[xy, np.full(4, c[2] - half[2])]
    top = np.c_[xy, np.full(4, c[2] + half[2])]
    return np.vstack([bottom, top])


_BOX_EDGES = [(i, (i + 1) % 4) for i in range(4)]
_BOX_EDGES += [(i + 4, (i + 1) % 4 + 4) for i in range(4)] + [(i, i + 4) for i in range(4)]


def _nice_length(span: float) -> float:
    """A 1-2-5 length close to a fifth of `span` for the scale bar."""
    target = max(span / 5.0, 1e-6)
    base = 10.0 ** math.floor(math.log10(target))
    return max(m * base for m in (1.0, 2.0, 5.0) if m * base <= target)


def _fit_limits(lo: np.ndarray, hi: np.ndarray, box_w: float, box_h: float) -> tuple:
    """Limits around [lo, hi] with a margin, widened along one axis to the axes' pixel aspect so
    one metre is as long across as up (the axes box then never moves: predictable pixels)."""
    span = np.maximum(hi - lo, 1e-3)
    lo, hi = lo - 0.04 * span, hi + 0.04 * span
    span = hi - lo
    scale = max(span[0] / box_w, span[1] / box_h)  # metres per pixel
    mid = (lo + hi) / 2.0
    half = np.array([box_w, box_h]) * scale / 2.0
    return (mid[0] - half[0], mid[0] + half[0]), (mid[1] - half[1], mid[1] + half[1])


class _Labels:
    """Greedy label placement: a label whose box would overlap one already placed is left out
    (kitchen-sized results have hundreds of objects; overlapping ids are unreadable anyway).
    Boxes are estimated in display pixels from the text length, which is close enough here."""

    def __init__(self, ax: Axes, fs: float, dpi: float, halo: list) -> None:
        self.ax, self.fs, self.dpi, self.halo = ax, fs, dpi, halo
        self.boxes: list[tuple[float, float, float, float]] = []
        self.hidden = 0

    def _box(self, xy_px: np.ndarray, text: str, size: float, dx: float, dy: float, va: str):
        h = size * self.dpi / 72.0 * 1.15
        w = size * self.dpi / 72.0 * 0.62 * len(text)
        x0 = xy_px[0] + dx
        y0 = xy_px[1] + dy - (h if va == "top" else 0.0)
        return x0, y0, x0 + w, y0 + h

    def _overlap(self, b: tuple[float, float, float, float]) -> float:
        """Pixel area `b` shares with the labels already placed."""
        return sum(
            max(0.0, min(b[2], o[2]) - max(b[0], o[0]))
            * max(0.0, min(b[3], o[3]) - max(b[1], o[1]))
            for o in self.boxes
        )

    def place(
        self,
        anchors: list[np.ndarray],
        text: str,
        *,
        size: float,
        color,
        va: str = "top",
        bold: bool = False,
        force: bool = False,
    ) -> bool:
        """Put `text` at the first anchor (picture metres) where it overlaps nothing placed;
        with `force`, else at the anchor where it overlaps least. Returns whether it was drawn."""
        dx, dy = 3.0, (-3.0 if va == "top" else 2.0)
        to_px = self.ax.transData.transform
        boxes = [self._box(to_px(a), text, size, dx, dy, va) for a in anchors]
        overlaps = [self._overlap(b) for b in boxes]
        best = next((i for i, o in enumerate(overlaps) if o == 0.0), None)
        if best is None and force:
            best = int(np.argmin(overlaps))
        if best is None:
            self.hidden += 1
            return False
        self.boxes.append(boxes[best])
        self.ax.annotate(
            text,
            xy=anchors[best],
            xytext=(dx, dy),
            textcoords="offset pixels",
            ha="left",
            va=va,
            fontsize=size,
            fontweight="bold" if bold else "normal",
            color=color,
            path_effects=self.halo,
            zorder=6,
            annotation_clip=False,
        )
        return True


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
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    basis = view_basis(view)
    colours = point_colours(frame, color)
    w_px, h_px = (int(v) for v in size)
    if w_px < 200 or h_px < 150 or not dpi > 0:
        raise SupportNodeError(f"picture size {w_px}x{h_px} at {dpi} dpi: need at least 200x150")
    if max_points < 1:
        raise SupportNodeError(f"max_points must be at least 1, got {max_points}")
    result = frame.result
    n_all = len(frame.points)

    # Text size follows the picture so small and large ones stay legible; margins follow text.
    fs = 9.0 * float(np.clip(min(w_px, h_px) / 900.0, 0.7, 2.0))
    line = fs * dpi / 72.0 * 1.5  # one line of text, px
    fig = Figure(figsize=(w_px / dpi, h_px / dpi), dpi=dpi, facecolor="white")
    FigureCanvasAgg(fig)  # attaches itself: savefig and canvas.draw work without pyplot
    left, bottom, right = 4.5 * line, 3.2 * line, 1.0 * line
    if view == "oblique":  # no tick labels
        left, bottom = 1.0 * line, 2.0 * line
    legend = _place_legend(fig, _legend_handles(frame, color, fs), left, 1.7 * line, fs, w_px)
    top = 1.7 * line + legend.get_window_extent().height + 0.6 * line
    box = [left / w_px, bottom / h_px, 1 - (left + right) / w_px, 1 - (bottom + top) / h_px]
    if box[2] <= 0.1 or box[3] <= 0.1:
        raise SupportNodeError(f"picture size {w_px}x{h_px} is too small for its text")
    ax = fig.add_axes(box)
    box_w, box_h = box[2] * w_px, box[3] * h_px

    lo, hi = _extent(frame, basis)
    xlim, ylim = _fit_limits(lo, hi, box_w, box_h)
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal", adjustable="datalim")  # equal by construction already; keep it so
    ax.set_autoscale_on(False)  # adding collections must not move the limits

    drawn = _draw_points(ax, frame, colours, basis, view, max_points, seed, box_w * box_h, dpi)

    halo = [patheffects.withStroke(linewidth=max(2.0, fs / 3.0), foreground="white")]
    labels = _Labels(ax, fs, dpi, halo)
    lw = max(1.0, fs / 6.0)
    _draw_surfaces(ax, result, basis, labels, fs, lw)
    _draw_objects(ax, result, basis, view, color, labels, fs, lw)
    _draw_discs(ax, result, basis, lw)

    fig.text(
        box[0],
        1 - 0.6 * line / h_px,
        _title(frame, view, drawn, n_all),
        fontsize=fs * 1.2,
        va="top",
    )
    _scale_bar(ax, xlim, ylim, fs)
    _axes_labels(ax, view, fs)
    notes = list(frame.notes)
    if labels.hidden:
        notes.append(
            f"{labels.hidden} crowded object label{'s' if labels.hidden > 1 else ''} left out"
        )
    if notes:
        fig.text(
            1 - 0.3 * line / w_px, 0.3 * line / h_px, "; ".join(notes),
            ha="right", va="bottom", fontsize=fs * 0.85, color="0.3",
        )  # fmt: skip
    return fig, ax


def _extent(frame: Frame, basis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Picture-plane box (lo, hi), metres: the central points (every point, not only the drawn
    ones) and the surfaces found. Robust percentiles, so that a few far returns (a depth
    camera's 10 m outliers) do not shrink the scene into a corner; they are drawn at the edge."""
    parts = [r @ basis[:2].T for s in frame.result["surfaces"] for r in _rings3(s)]
    if len(frame.points):
        xy = frame.points @ basis[:2].T
        lo, hi = np.percentile(xy, [_ROBUST_PERCENT, 100 - _ROBUST_PERCENT], axis=0)
        margin = 0.1 * (hi - lo)  # the central points and a little more, within the data
        lo, hi = np.maximum(lo - margin, xy.min(0)), np.minimum(hi + margin, xy.max(0))
        parts.append(np.vstack([lo, hi]))
    central = np.vstack(parts) if parts else np.zeros((1, 2))
    lo, hi = central.min(axis=0), central.max(axis=0)
    # objects inside that box count whole (a box is not cut at the edge), far ones do not
    for o in frame.result["objects"]:
        corners = _obb_corners(o) @ basis[:2].T
        if np.all((corners.mean(0) >= lo) & (corners.mean(0) <= hi)):
            lo, hi = np.minimum(lo, corners.min(0)), np.maximum(hi, corners.max(0))
    return lo, hi


def _rings3(s: dict) -> list[np.ndarray]:
    """A surface's outline rings, closed, as (K+1, 3) polylines at its height (outer first)."""
    h = float(s["height"])
    out = []
    for ring in s.get("outline", []):
        r = np.asarray(ring, dtype=np.float64).reshape(-1, 2)
        r = np.vstack([r, r[:1]])
        out.append(np.c_[r, np.full(len(r), h)])
    return out


def _draw_points(
    ax: Axes,
    frame: Frame,
    colours: np.ndarray,
    basis: np.ndarray,
    view: str,
    max_points: int,
    seed: int,
    area_px: float,
    dpi: float,
) -> int:
    """Scatter a seeded subset, far points first so nearer ones cover them (top view: an
    object's top hides the table under it). Returns how many were drawn."""
    n = len(frame.points)
    idx = np.arange(n)
    if n > max_points:
        idx = np.sort(np.random.default_rng(seed).choice(n, max_points, replace=False))
    pts = frame.points[idx]
    depth = pts @ basis[2]
    order = np.argsort(depth, kind="stable")
    xy = pts[order] @ basis[:2].T
    # outliers beyond the limits (see _extent) are drawn on the edge, not lost
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    xy = np.c_[np.clip(xy[:, 0], x0, x1), np.clip(xy[:, 1], y0, y1)]
    rgb = colours[idx][order]
    if view != "top" and len(depth) > 1:
        # Side and oblique views have no occlusion worth the name with sparse points: fade far
        # points towards white so the near side reads first. The top view keeps pure colours
        # (heights are in the labels; tests check colours there).
        d = depth[order]
        far = (d.max() - d) / max(float(np.ptp(d)), 1e-9)
        rgb = rgb + (1.0 - rgb) * (0.7 * far)[:, None]
    # Marker about the mean on-screen spacing of the drawn points, 1-5 px.
    d_px = float(np.clip(0.9 * math.sqrt(area_px / max(len(xy), 1)), 1.0, 5.0))
    ax.scatter(
        xy[:, 0],
        xy[:, 1],
        s=(d_px * 72.0 / dpi) ** 2,
        c=rgb,
        marker="s",
        linewidths=0,
        antialiased=False,
        zorder=1,
    )
    return len(idx)


def _draw_surfaces(ax: Axes, result: dict, basis: np.ndarray, labels: _Labels, fs, lw) -> None:
    """Outline rings at each surface's height (outer solid, holes dashed) and an id + height
    label inside the outer ring's top-left corner, else its bottom-left, else the centroid."""
    from matplotlib.collections import LineCollection

    outer, holes = [], []
    for s in result["surfaces"]:
        rings = [r @ basis[:2].T for r in _rings3(s)]
        outer += rings[:1]
        holes += rings[1:]
        h = float(s["height"])
        c = np.asarray(s.get("centroid", [0.0, 0.0, h]), dtype=np.float64)
        anchors = [np.r_[c[0], c[1], h] @ basis[:2].T]
        if rings:
            r = rings[0]
            # vertices nearest the corners of the ring's box: a notch must not pull the label
            lo, hi = r.min(axis=0), r.max(axis=0)
            top_left = r[np.argmin(np.hypot(r[:, 0] - lo[0], r[:, 1] - hi[1]))]
            bottom_left = r[np.argmin(np.hypot(r[:, 0] - lo[0], r[:, 1] - lo[1]))]
            top_right = r[np.argmin(np.hypot(r[:, 0] - hi[0], r[:, 1] - hi[1]))]
            anchors = [top_left, *anchors, bottom_left, top_right]
        labels.place(anchors, f"S{int(s['id'])}  {h:.2f} m", size=fs, color=OUTLINE_RGB,
                     bold=True, force=True)  # fmt: skip
    ax.add_collection(LineCollection(outer, colors=[OUTLINE_RGB], linewidths=lw, zorder=3))
    ax.add_collection(
        LineCollection(holes, colors=[OUTLINE_RGB], linewidths=lw * 0.7, linestyles="--", zorder=3)
    )


def _draw_objects(
    ax: Axes, result: dict, basis: np.ndarray, view: str, color: str, labels: _Labels, fs, lw
) -> None:
    """Oriented boxes: the top rectangle in the top view (the rest projects onto it), all 12
    edges otherwise; objects on no surface dotted grey. Ids by a top corner, largest first."""
    from matplotlib.collections import LineCollection

    palette = _palette(20, "tab20")
    thin = 1.0 if view == "top" else 0.7  # 12 edges per box crowd the other views
    groups: dict[bool, tuple[list, list]] = {True: ([], []), False: ([], [])}
    # supported objects get their labels first: they are what the picture is about
    ordered = sorted(result["objects"], key=lambda o: (o.get("surface_id") is None, int(o["id"])))
    for o in ordered:
        supported = o.get("surface_id") is not None
        corners = _obb_corners(o) @ basis[:2].T
        c = BOX_RGB if supported else OFF_BOX_RGB
        if color == "id":
            c = tuple(palette[int(o["id"]) % 20] * 0.7)  # darker than the object's points
        segs, cols = groups[supported]
        for a, b in _BOX_EDGES[4:8] if view == "top" else _BOX_EDGES:
            segs.append(corners[[a, b]])
            cols.append(c)
        tops = corners[4:]
        tip = tops[np.argmax(tops[:, 1] + 1e-3 * tops[:, 0])]
        labels.place([tip], f"#{int(o['id'])}", size=fs * (0.8 if supported else 0.65),
                     color=c, va="bottom")  # fmt: skip
    for supported, (segs, cols) in groups.items():
        if segs:
            ax.add_collection(
                LineCollection(
                    segs,
                    colors=cols,
                    linewidths=lw * thin * (1.0 if supported else 0.7),
                    linestyles="-" if supported else ":",
                    alpha=1.0 if view == "top" else 0.8,
                    zorder=4 if supported else 2,
                )
            )


def _draw_discs(ax: Axes, result: dict, basis: np.ndarray, lw: float) -> None:
    """The largest free disc of each surface: a dashed circle at the surface's height (an
    ellipse in the oblique view, a segment in the side view)."""
    from matplotlib.collections import LineCollection

    heights = {int(s["id"]): float(s["height"]) for s in result["surfaces"]}
    t = np.linspace(0.0, 2.0 * math.pi, _DISC_VERTICES + 1)
    discs = []
    for f in result["free_space"]:
        centre, r = f.get("disc_center"), float(f["disc_radius"])
        if centre is None or None in centre or not r > 0:
            continue  # a surface fully covered has no disc
        h = heights.get(int(f["surface_id"]), 0.0)
        ring = np.c_[centre[0] + r * np.cos(t), centre[1] + r * np.sin(t), np.full(len(t), h)]
        discs.append(ring @ basis[:2].T)
    if discs:
        ax.add_collection(
            LineCollection(discs, colors=[DISC_RGB], linewidths=lw * 1.3, linestyles="--", zorder=3)
        )


def _legend_handles(frame: Frame, color: str, fs: float) -> list:
    """Legend entries; counts come from the full frame and result, not the drawn subset."""
    from matplotlib.lines import Line2D

    objects = frame.result["objects"]
    n_surf = int(np.count_nonzero(frame.surface >= 0))
    n_on = sum(o.get("surface_id") is not None for o in objects)
    lw = max(1.0, fs / 6.0)

    def dot(rgb: tuple, label: str) -> Line2D:
        return Line2D([], [], marker="s", ls="", color=rgb, markersize=fs * 0.9, label=label)

    if color == "class":
        handles = [
            dot(SURFACE_RGB, f"surface points ({n_surf:,})"),
            dot(OTHER_RGB, f"other points ({len(frame.points) - n_surf:,})"),
        ]
    else:
        handles = [
            dot(tuple(_palette(10, "tab10")[0]), f"surface points, colour by id ({n_surf:,})"),
            dot(tuple(_palette(20, "tab20")[1]), "object points, colour by id"),
            dot(GREY_RGB, "other points"),
        ]
    return [
        *handles,
        Line2D([], [], color=OUTLINE_RGB, lw=lw, label=f"surface outline ({len(frame.result['surfaces'])})"),
        Line2D([], [], color=BOX_RGB, lw=lw, label=f"object box ({n_on} on a surface)"),
        Line2D([], [], color=OFF_BOX_RGB, lw=lw, ls=":", label=f"on no surface ({len(objects) - n_on})"),
        Line2D([], [], color=DISC_RGB, lw=lw * 1.3, ls="--", label="largest free disc"),
    ]  # fmt: skip


def _place_legend(fig: Figure, handles: list, left: float, top: float, fs: float, w_px: int):
    """The legend in as many columns as fit the picture's width (measured, not guessed), its
    top-left corner `left`, `top` pixels from the figure's top-left."""
    h_px = fig.get_size_inches()[1] * fig.dpi
    renderer = fig.canvas.get_renderer()
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


def _scale_bar(ax: Axes, xlim: tuple, ylim: tuple, fs: float) -> None:
    """A 1-2-5 metre bar; picture-plane x is true length in every view (orthographic)."""
    from mpl_toolkits.axes_grid1.anchored_artists import AnchoredSizeBar

    length = _nice_length(xlim[1] - xlim[0])
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
