"""Where pictures get their data: a :class:`Frame` (points, labels, parsed result) from a
`supportnode detect` output folder. A later source (a recording) only has to build Frames; the
drawing code never reads files."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from supportnode.errors import SupportNodeError


@dataclass
class Frame:
    """Everything one picture shows.

    points: (N, 3) float64 metres in the detection frame (z up, aligned when `--align` ran).
    surface: (N,) int32 surface id per point, -1 on none. object: (N,) int32 object id per point,
    -1 on none, or None when unknown (objects are then still drawn as boxes, their points as
    "other"). result: the parsed result.json (surfaces, objects, free_space, input, ...).
    name: a short title (the input's file stem).
    """

    points: np.ndarray
    surface: np.ndarray
    object: np.ndarray | None
    result: dict[str, Any]
    name: str = ""
    notes: list[str] = field(default_factory=list)  # caveats worth a line on the picture


def load_result(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Parse and check ``result.json`` (or the folder holding it); one-line SupportNodeError."""
    p = Path(path)
    if p.is_dir():
        p = p / "result.json"
    if not p.is_file():
        if not p.parent.is_dir():
            raise SupportNodeError(f"{p.parent}: no such folder")
        raise SupportNodeError(f"{p}: no such file (is {p.parent} a detect output folder?)")
    try:
        result = json.loads(p.read_text())
    except UnicodeDecodeError as err:
        raise SupportNodeError(f"{p}: not a text file") from err
    except json.JSONDecodeError as err:
        raise SupportNodeError(f"{p}: not valid JSON (line {err.lineno}: {err.msg})") from err
    except OSError as err:
        raise SupportNodeError(f"{p}: cannot read ({err.strerror or err})") from err
    if not isinstance(result, dict) or not isinstance(result.get("surfaces"), list):
        raise SupportNodeError(f"{p}: not a detect result (no 'surfaces' list)")
    # --no-objects results have empty lists; older or hand-made ones may lack the keys entirely
    for key in ("objects", "free_space"):
        if not isinstance(result.setdefault(key, []), list):
            raise SupportNodeError(f"{p}: {key!r} must be a list")
    try:
        _check_result(result)
    except (KeyError, TypeError, ValueError, IndexError) as err:
        raise SupportNodeError(f"{p}: malformed result ({type(err).__name__}: {err})") from err
    return result


def _check_result(result: dict[str, Any]) -> None:
    """Touch every field the drawing uses so that a bad file fails here, in one line, and not
    halfway through a figure."""
    for s in result["surfaces"]:
        _ = int(s["id"]), float(s["height"])
        for ring in s.get("outline", []):
            if np.asarray(ring, dtype=float).reshape(-1, 2).shape[0] == 0:
                raise ValueError(f"surface {s['id']}: empty outline ring")
    for o in result["objects"]:
        _ = int(o["id"]), float(o["obb_yaw"])
        for key in ("obb_center", "obb_size"):
            if np.asarray(o[key], dtype=float).shape != (3,):
                raise ValueError(f"object {o['id']}: {key} needs 3 values")
    for f in result["free_space"]:
        _ = int(f["surface_id"]), float(f["disc_radius"])


def load_result_dir(result_dir: str | os.PathLike[str]) -> Frame:
    """Build a Frame from a `supportnode detect` output folder.

    Points come from ``<name>_detected.ply`` and ``<name>_not_detected.ply``; when those are
    absent, from the input cloud named in result.json (rotated by its gravity rotation, if any)
    with ``labels.npz``. Raises SupportNodeError with one line on any problem.
    """
    from supportnode.io.clouds import read_cloud

    d = Path(result_dir)
    if not d.exists():
        raise SupportNodeError(f"{d}: no such folder")
    if not d.is_dir():
        raise SupportNodeError(f"{d}: not a folder (expected a `supportnode detect` output)")
    result = load_result(d)
    inp = result.get("input") or {}
    name = Path(str(inp.get("path", ""))).stem or d.name
    labels = _load_labels(d / "labels.npz")
    det, rest = _find_plys(d, name)
    notes: list[str] = []
    if det is not None and rest is not None:
        a, b = read_cloud(det, allow_empty=True), read_cloud(rest, allow_empty=True)
        points = np.vstack([a.points, b.points])
        surface, obj = _labels_for_plys(labels, len(a), len(b), inp, notes)
        if surface is None:  # labels unusable: the PLY split still tells surface from rest
            surface = np.r_[np.zeros(len(a), np.int32), np.full(len(b), -1, np.int32)]
    else:
        points, surface, obj = _from_input(d, inp, labels, result)
    return Frame(points=points, surface=surface, object=obj, result=result, name=name, notes=notes)


def _load_labels(path: Path) -> dict[str, np.ndarray] | None:
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: np.asarray(z[k]) for k in ("surface", "object", "finite") if k in z.files}
    except (OSError, ValueError, EOFError) as err:
        raise SupportNodeError(f"{path}: cannot read ({' '.join(str(err).split())})") from err


def _find_plys(d: Path, name: str) -> tuple[Path | None, Path | None]:
    """The report's two clouds; by the input's name first, else the only pair in the folder
    (the folder may have been renamed or the input path rewritten)."""
    det, rest = d / f"{name}_detected.ply", d / f"{name}_not_detected.ply"
    if det.is_file() and rest.is_file():
        return det, rest
    pairs = [
        (p, p.with_name(p.name[: -len("_detected.ply")] + "_not_detected.ply"))
        for p in d.glob("*_detected.ply")
        if not p.name.endswith("_not_detected.ply")
    ]
    pairs = [(a, b) for a, b in pairs if b.is_file()]
    return pairs[0] if len(pairs) == 1 else (None, None)


def _labels_for_plys(
    labels: dict[str, np.ndarray] | None,
    n_det: int,
    n_rest: int,
    inp: dict[str, Any],
    notes: list[str],
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """Per-point labels in PLY order (detected rows, then the rest).

    The PLYs hold the file's finite rows split by `surface >= 0`, each in row order, so the
    labels line up exactly when no row was dropped. Dropped (NaN) rows are -1 in labels.npz just
    like off-surface rows, so then only the surface side can be matched; object ids are unknown.
    """
    if labels is None or "surface" not in labels:
        notes.append("no labels.npz: points coloured by class only")
        return None, None
    surf = labels["surface"].astype(np.int32, copy=False)
    on = surf >= 0
    if int(on.sum()) != n_det:
        notes.append("labels.npz does not match the clouds: points coloured by class only")
        return None, None
    s_det = surf[on]
    surface = np.r_[s_det, np.full(n_rest, -1, np.int32)]
    obj = labels.get("object")
    if obj is None:
        return surface, None
    obj = obj.astype(np.int32, copy=False)
    finite = labels.get("finite")  # which rows the clouds hold (written since NaN rows count)
    if finite is None and len(surf) == n_det + n_rest:
        finite = np.ones(len(surf), dtype=bool)
    if finite is not None and int(finite.sum()) == n_det + n_rest:
        kept_surf, kept_obj = surf[finite], obj[finite]
        return surface, np.r_[np.full(n_det, -1, np.int32), kept_obj[kept_surf < 0]]
    notes.append("NaN rows dropped: object points not matched to ids")
    return surface, None


def _from_input(
    d: Path, inp: dict[str, Any], labels: dict[str, np.ndarray] | None, result: dict[str, Any]
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Points from the input cloud named in result.json, labels from labels.npz."""
    from supportnode.io.clouds import read_cloud

    raw = inp.get("path")
    if not raw:
        raise SupportNodeError(f"{d}: no *_detected.ply clouds and no input path in result.json")
    if labels is None or "surface" not in labels:
        raise SupportNodeError(f"{d}: no *_detected.ply clouds and no labels.npz")
    # a relative input path was relative to where detect ran: try there, then beside the folder
    candidates = [Path(raw)] if Path(raw).is_absolute() else [Path(raw), d.parent / Path(raw).name]
    path = next((p for p in candidates if p.is_file()), None)
    if path is None:
        raise SupportNodeError(f"{d}: no *_detected.ply clouds and input {raw} not found")
    cloud = read_cloud(path)
    if len(labels["surface"]) != cloud.input_count:
        raise SupportNodeError(
            f"{d}/labels.npz has {len(labels['surface'])} rows but {path} has {cloud.input_count}"
        )
    points = cloud.points
    rotation = (result.get("gravity") or {}).get("rotation")
    if rotation is not None:  # labels and result live in the aligned frame; so must the points
        points = points @ np.asarray(rotation, dtype=np.float64).reshape(3, 3).T
    surface = labels["surface"][cloud.source_index].astype(np.int32)
    obj = labels.get("object")
    obj = None if obj is None else obj[cloud.source_index].astype(np.int32)
    return points, surface, obj
