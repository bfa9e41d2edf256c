"""The picture's layers on matplotlib axes: points, surface outlines, object boxes, free discs,
labels and legend entries."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from supportnode.errors import SupportNodeError
from supportnode.render.projection import BOX_EDGES, COLOR_MODES, obb_corners, rings3
from supportnode.render.source import Frame

if TYPE_CHECKING:  # matplotlib is an optional extra: never imported at module level
    from matplotlib.axes import Axes

# The report's colours, slightly softened so labels stay readable on top of them.
SURFACE_RGB = (0.90, 0.10, 0.10)
OTHER_RGB = (0.15, 0.70, 0.15)
GREY_RGB = (0.62, 0.62, 0.62)
OUTLINE_RGB = (0.0, 0.0, 0.0)
BOX_RGB = (0.10, 0.25, 1.0)
OFF_BOX_RGB = (0.35, 0.35, 0.35)  # objects standing on no surface (walls, clutter)
DISC_RGB = (0.95, 0.0, 0.95)
_DISC_VERTICES = 96


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


class Labels:
    """Greedy label placement: a label whose box would overlap one already placed is left out
    (kitchen-sized results have hundreds of objects; overlapping ids are unreadable anyway).
    Boxes are estimated in display pixels from the text length, which is close enough here."""

    def __init__(self, ax: Axes, fs: float, dpi: float, halo: list[Any]) -> None:
        self.ax, self.fs, self.dpi, self.halo = ax, fs, dpi, halo
        self.boxes: list[tuple[float, float, float, float]] = []
        self.hidden = 0

    def _box(
        self, xy_px: np.ndarray, text: str, size: float, dx: float, dy: float, va: str
    ) -> tuple[float, float, float, float]:
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
        color: Any,
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
            xy=(float(anchors[best][0]), float(anchors[best][1])),
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


def draw_points(
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
    # outliers beyond the limits (see extent) are drawn on the edge, not lost
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


def draw_surfaces(
    ax: Axes, result: dict[str, Any], basis: np.ndarray, labels: Labels, fs: float, lw: float
) -> None:
    """Outline rings at each surface's height (outer solid, holes dashed) and an id + height
    label inside the outer ring's top-left corner, else its bottom-left, else the centroid."""
    from matplotlib.collections import LineCollection

    outer, holes = [], []
    for s in result["surfaces"]:
        rings = [r @ basis[:2].T for r in rings3(s)]
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


def draw_objects(
    ax: Axes,
    result: dict[str, Any],
    basis: np.ndarray,
    view: str,
    color: str,
    labels: Labels,
    fs: float,
    lw: float,
) -> None:
    """Oriented boxes: the top rectangle in the top view (the rest projects onto it), all 12
    edges otherwise; objects on no surface dotted grey. Ids by a top corner, largest first."""
    from matplotlib.collections import LineCollection

    palette = _palette(20, "tab20")
    thin = 1.0 if view == "top" else 0.7  # 12 edges per box crowd the other views
    groups: dict[bool, tuple[list[Any], list[Any]]] = {True: ([], []), False: ([], [])}
    # supported objects get their labels first: they are what the picture is about
    ordered = sorted(result["objects"], key=lambda o: (o.get("surface_id") is None, int(o["id"])))
    for o in ordered:
        supported = o.get("surface_id") is not None
        corners = obb_corners(o) @ basis[:2].T
        c = BOX_RGB if supported else OFF_BOX_RGB
        if color == "id":
            c = tuple(palette[int(o["id"]) % 20] * 0.7)  # darker than the object's points
        segs, cols = groups[supported]
        for a, b in BOX_EDGES[4:8] if view == "top" else BOX_EDGES:
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


def draw_discs(ax: Axes, result: dict[str, Any], basis: np.ndarray, lw: float) -> None:
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


def legend_handles(frame: Frame, color: str, fs: float) -> list[Any]:
    """Legend entries; counts come from the full frame and result, not the drawn subset."""
    from matplotlib.lines import Line2D

    objects = frame.result["objects"]
    n_surf = int(np.count_nonzero(frame.surface >= 0))
    n_on = sum(o.get("surface_id") is not None for o in objects)
    lw = max(1.0, fs / 6.0)

    def dot(rgb: tuple[float, float, float], label: str) -> Line2D:
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
