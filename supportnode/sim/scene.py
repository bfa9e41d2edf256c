"""Scene files (YAML) -> typed, posed primitives with ground-truth labels.

A scene file::

    name: demo                      # optional, defaults to the file stem
    description: one line           # optional
    trajectory: {kind: circle, center: [0, 0, 1.2], radius: 3, target: [0, 0, 0.5]}  # optional
    define:                         # optional reusable parts, used with `use:`
      chair:
        - {kind: box, name: seat, size: [0.45, 0.45, 0.04], xyz: [0, 0, 0.45],
           role: surface, surface: seat}
        - {kind: cylinder, radius: 0.02, height: 0.43, xyz: [0.2, 0.2, 0.215], role: structure}
    primitives:
      - {kind: box, name: floor, size: [6, 6, 0.02], xyz: [0, 0, -0.01], role: surface,
         surface: floor}
      - {use: chair, name: chair_a, xyz: [1, 0, 0], rpy: [0, 0, 90]}
      - {kind: group, name: lamp, xyz: [0, 0, 0.5], role: object, object: lamp, children: [...]}

Every primitive has `kind` (box, cylinder, sphere, cone, cup, bowl, torus, group) or `use`, an optional `name`,
`xyz` (metres) and `rpy` (degrees; R = Rz(yaw) Ry(pitch) Rx(roll), child poses compose with their
parent's), and a `role`: `surface` (box or cylinder; only the +z face is a support surface, its
other faces are structure; needs `surface: NAME`), `structure`, or `object` (needs `object: NAME`;
parts sharing a name form one object). Groups and `use` pass `role`, `object` and `surface` down
to children that do not set them. Names of objects and surfaces inside a `use` are scoped by the
instance name ("chair_a/seat"), so two chairs give two seats. Ids are assigned in file order:
surfaces 0..S-1, objects 0..O-1. Sizes: box `size: [x, y, z]`; cylinder and cone `radius`,
`height`; sphere `radius`; cup `radius`, `height`, `thickness`; bowl `radius` (rim), `height`,
`thickness`, `base_radius`; torus `major_radius`, `minor_radius`, optional `arc_deg` (metres and
degrees, centred on the pose, see `supportnode.sim.primitives`).

Errors raise `SceneError` naming file, line and key.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from supportnode.errors import SceneError
from supportnode.sim.primitives import KINDS, Bowl, Box, Cone, Cup, Cylinder, Shape, Sphere, Torus
from supportnode.sim.scene_model import Primitive, Scene, pose_matrix, rpy_matrix
from supportnode.yamlnodes import LineMap, LineSeq, compose, line_tree, read_text

__all__ = [
    "Primitive",
    "Scene",
    "bundled_scenes",
    "load_scene",
    "parse_scene",
    "pose_matrix",
    "rpy_matrix",
    "scene_path",
]

SCENES_DIR = Path(__file__).resolve().parent / "scenes"  # shipped inside the package
ROLES = ("surface", "structure", "object")
_TOP_KEYS = {"name", "description", "trajectory", "define", "primitives"}
_COMMON_KEYS = {"kind", "name", "xyz", "rpy", "role", "object", "surface"}
_SHAPE_KEYS = {  # required keys of each kind
    "box": {"size"},
    "cylinder": {"radius", "height"},
    "cone": {"radius", "height"},
    "sphere": {"radius"},
    "cup": {"radius", "height", "thickness"},
    "bowl": {"radius", "height", "thickness", "base_radius"},
    "torus": {"major_radius", "minor_radius"},
    "group": {"children"},
    "use": {"use"},
}
_OPTIONAL_KEYS = {"torus": {"arc_deg"}}
_SHAPES = {
    "box": Box,
    "cylinder": Cylinder,
    "cone": Cone,
    "sphere": Sphere,
    "cup": Cup,
    "bowl": Bowl,
    "torus": Torus,
}
_TRAJ_KEYS = {
    "circle": {"kind", "center", "radius", "target", "start_deg", "arc_deg", "level"},
    "line": {"kind", "start", "end", "target", "level"},
}


# --- Parsing ----------------------------------------------------------------------------------


class _Parser:
    """Walks the loaded YAML, composing poses and assigning ids; every error names file:line."""

    def __init__(self, source: str) -> None:
        self.source = source
        self.defines: LineMap = LineMap()
        self.prims: list[Primitive] = []
        self.surfaces: dict[str, int] = {}
        self.objects: dict[str, int] = {}
        self.use_counts: dict[str, int] = {}

    def fail(self, line: int, msg: str) -> SceneError:
        return SceneError(f"{self.source}:{line}: {msg}")

    def line_of(self, m: LineMap, key: str) -> int:
        return m.key_lines.get(key, m.line) if isinstance(m, LineMap) else 0

    def numbers(
        self, m: LineMap, key: str, n: int, label: str, positive: bool = False
    ) -> list[float]:
        value = m[key]
        values = value if isinstance(value, list) else [value]
        ok = len(values) == n and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            for v in values
        )
        if ok and positive:
            ok = all(v > 0 for v in values)
        if not ok:
            what = f"{n} {'positive ' if positive else ''}number{'s' if n > 1 else ''}"
            raise self.fail(
                self.line_of(m, key), f"{label}: key {key!r} must be {what}, got {value!r}"
            )
        return [float(v) for v in values]

    def name_value(self, m: LineMap, key: str, label: str) -> str:
        value = m[key]
        if isinstance(value, bool) or not isinstance(value, (str, int)):
            raise self.fail(self.line_of(m, key), f"{label}: key {key!r} must be a name or an id")
        return str(value)

    def parse(self, doc: Any) -> None:
        if not isinstance(doc, LineMap):
            raise self.fail(getattr(doc, "line", 1), "a scene must be a mapping with 'primitives'")
        for key in doc:
            if key not in _TOP_KEYS:
                expected = ", ".join(sorted(_TOP_KEYS))
                raise self.fail(doc.key_lines[key], f"unknown key {key!r} (expected {expected})")
        if "primitives" not in doc:
            raise self.fail(doc.line, "missing key 'primitives'")
        if "define" in doc:
            if not isinstance(doc["define"], LineMap):
                raise self.fail(doc.key_lines["define"], "'define' must map names to lists")
            self.defines = doc["define"]
        self.children(doc["primitives"], self.line_of(doc, "primitives"), np.eye(4), {}, "", "", [])
        if not self.prims:
            raise self.fail(doc.line, "the scene has no primitives")

    def children(
        self,
        items: Any,
        line: int,
        parent: np.ndarray,
        inherited: dict[str, Any],
        scope: str,
        path: str,
        stack: list[str],
    ) -> None:
        if not isinstance(items, LineSeq):
            raise self.fail(line, f"{path or 'primitives'}: expected a list of primitives")
        for i, item in enumerate(items):
            label_path = f"{path}.{i}" if path else str(i)
            if not isinstance(item, LineMap):
                raise self.fail(items.item_lines[i], f"primitive {label_path}: expected a mapping")
            self.item(item, parent, inherited, scope, label_path, stack)

    def item(
        self,
        m: LineMap,
        parent: np.ndarray,
        inherited: dict[str, Any],
        scope: str,
        path: str,
        stack: list[str],
    ) -> None:
        name = self.name_value(m, "name", f"primitive {path}") if "name" in m else ""
        label = f"primitive {name!r}" if name else f"primitive {path}"
        kind = self.kind(m, label)
        xyz = self.numbers(m, "xyz", 3, label) if "xyz" in m else [0.0, 0.0, 0.0]
        rpy = self.numbers(m, "rpy", 3, label) if "rpy" in m else [0.0, 0.0, 0.0]
        pose = parent @ pose_matrix(xyz, rpy)
        labels = dict(inherited)
        for key in ("role", "object", "surface"):
            if key in m:
                labels[key] = (self.name_value(m, key, label), self.line_of(m, key), scope)

        if kind == "group":
            self.children(
                m["children"], self.line_of(m, "children"), pose, labels, scope, path, stack
            )
            return
        if kind == "use":
            self.use(m, name, label, pose, labels, scope, stack)
            return
        self.leaf(m, kind, name, label, pose, labels)

    def kind(self, m: LineMap, label: str) -> str:
        """The item's kind (``use`` for an instance of a define), its keys checked for it."""
        if "use" in m:
            kind = "use"
        elif "kind" not in m:
            raise self.fail(m.line, f"{label}: missing key 'kind'")
        else:
            kind = m["kind"]
            if kind not in KINDS and kind != "group":
                expected = ", ".join((*KINDS, "group"))
                raise self.fail(
                    self.line_of(m, "kind"), f"{label}: unknown kind {kind!r} (expected {expected})"
                )
        allowed = _COMMON_KEYS | _SHAPE_KEYS[kind] | _OPTIONAL_KEYS.get(kind, set())
        for key in m:
            if key not in allowed:
                raise self.fail(
                    m.key_lines[key],
                    f"{label}: unknown key {key!r} for {kind} (expected {', '.join(sorted(allowed))})",
                )
        for key in sorted(_SHAPE_KEYS[kind]):
            if key not in m:
                raise self.fail(m.line, f"{label}: missing key {key!r}")
        return str(kind)

    def use(
        self,
        m: LineMap,
        name: str,
        label: str,
        pose: np.ndarray,
        labels: dict[str, Any],
        scope: str,
        stack: list[str],
    ) -> None:
        """An instance of a define: its primitives under ``pose``, ids scoped by the instance."""
        target = self.name_value(m, "use", label)
        line = self.line_of(m, "use")
        if target not in self.defines:
            known = ", ".join(sorted(map(str, self.defines))) or "none defined"
            raise self.fail(line, f"{label}: unknown define {target!r} (known: {known})")
        if target in stack:
            raise self.fail(line, f"{label}: define {target!r} uses itself")
        count = self.use_counts.get(target, 0)
        self.use_counts[target] = count + 1
        instance = name or f"{target}_{count}"
        new_scope = f"{scope}{instance}/"
        self.children(
            self.defines[target],
            self.defines.key_lines[target],
            pose,
            labels,
            new_scope,
            f"{target}",
            [*stack, target],
        )

    def leaf(
        self, m: LineMap, kind: str, name: str, label: str, pose: np.ndarray, labels: dict[str, Any]
    ) -> None:
        sizes: dict[str, Any] = {}
        for key in _SHAPE_KEYS[kind] | _OPTIONAL_KEYS.get(kind, set()):
            if key == "size":
                sizes[key] = tuple(self.numbers(m, key, 3, label, positive=True))
            elif key in m:
                sizes[key] = self.numbers(m, key, 1, label, positive=True)[0]
        try:
            shape: Shape = _SHAPES[kind](**sizes)
        except ValueError as err:  # a shape's own consistency checks (a wall thicker than a cup)
            raise self.fail(m.line, f"{label}: {err}") from None

        if "role" not in labels:
            raise self.fail(m.line, f"{label}: missing key 'role'")
        role, role_line, _ = labels["role"]
        if role not in ROLES:
            raise self.fail(
                role_line, f"{label}: unknown role {role!r} (expected {', '.join(ROLES)})"
            )
        object_id = surface_id = -1
        if role == "surface":
            if kind not in ("box", "cylinder"):
                raise self.fail(
                    role_line,
                    f"{label}: role 'surface' needs a box or a cylinder (a {kind} has no flat top)",
                )
            if "surface" not in labels:
                raise self.fail(m.line, f"{label}: missing key 'surface'")
            value, _, scope = labels["surface"]
            surface_id = self.surfaces.setdefault(scope + value, len(self.surfaces))
        elif role == "object":
            if "object" not in labels:
                raise self.fail(m.line, f"{label}: missing key 'object'")
            value, _, scope = labels["object"]
            object_id = self.objects.setdefault(scope + value, len(self.objects))
        index = len(self.prims)
        self.prims.append(
            Primitive(
                index, name or f"{kind}_{index}", shape, pose, role, object_id, surface_id, m.line
            )
        )


def _parse_trajectory(p: _Parser, doc: Any) -> dict[str, Any]:
    if not isinstance(doc, LineMap) or "trajectory" not in doc:
        return {}
    t = doc["trajectory"]
    line = doc.key_lines["trajectory"]
    if not isinstance(t, LineMap) or t.get("kind") not in _TRAJ_KEYS:
        raise p.fail(line, "trajectory: expected a mapping with kind circle or line")
    allowed = _TRAJ_KEYS[t["kind"]]
    for key in t:
        if key not in allowed:
            raise p.fail(
                t.key_lines[key],
                f"trajectory: unknown key {key!r} (expected {', '.join(sorted(allowed))})",
            )
    out: dict[str, Any] = {"kind": t["kind"]}
    for key in sorted(allowed - {"kind"}):
        if key in t:
            if key == "level":
                out[key] = bool(t[key])
            elif key in ("radius", "start_deg", "arc_deg"):
                out[key] = p.numbers(t, key, 1, "trajectory")[0]
            else:
                out[key] = p.numbers(t, key, 3, "trajectory")
    needed = {"circle": ("center", "radius"), "line": ("start", "end")}[t["kind"]]
    for key in needed:
        if key not in out:
            raise p.fail(t.line, f"trajectory: missing key {key!r}")
    return out


def parse_scene(text: str, source: str = "<string>", name: str = "scene") -> Scene:
    """A `Scene` from YAML text; `source` names the file in error messages."""
    parser = _Parser(source)
    doc = line_tree(compose(text, source, SceneError), source, SceneError)
    parser.parse(doc)
    return Scene(
        name=str(doc.get("name", name)),
        primitives=tuple(parser.prims),
        surface_names=tuple(parser.surfaces),
        object_names=tuple(parser.objects),
        description=str(doc.get("description", "")),
        trajectory=_parse_trajectory(parser, doc),
        source=source,
    )


def bundled_scenes() -> list[str]:
    """Names of the scenes shipped in supportnode/sim/scenes/."""
    return sorted(p.stem for p in SCENES_DIR.glob("*.yaml"))


def scene_path(name_or_path: str | Path) -> Path:
    """The YAML file for a bundled scene name (e.g. "shelf") or a path to a YAML file."""
    p = Path(name_or_path)
    if p.suffix in (".yaml", ".yml") or p.exists():
        if not p.is_file():
            raise SceneError(f"{p}: scene file not found")
        return p
    bundled = SCENES_DIR / f"{p.name}.yaml"
    if not bundled.is_file():
        names = ", ".join(bundled_scenes()) or "none found"
        raise SceneError(f"unknown scene {str(name_or_path)!r} (bundled: {names}; or a .yaml path)")
    return bundled


def load_scene(name_or_path: str | Path) -> Scene:
    """Load a bundled scene by name or a scene YAML file by path."""
    path = scene_path(name_or_path)
    return parse_scene(read_text(path, SceneError), source=path.name, name=path.stem)
