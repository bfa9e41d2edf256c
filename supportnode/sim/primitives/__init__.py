"""Geometric primitives in their own frame: ray intersection, area sampling and normals,
vectorised.

Frames follow URDF/SDF: every shape is centred on its origin. A box spans +-size/2; a cylinder has
its axis along z and spans z in [-height/2, height/2]; a cone has its base disc (radius) at
z = -height/2 and its apex at z = +height/2; a sphere is centred. A cup (a mug's body) and a
bowl are open vessels about z, base at -height/2, rim at +height/2; a torus lies in the xy plane
(an arc of it is centred on +x). The "top" face is the face whose outward normal is +z in the
shape's frame (box +z face, cylinder top disc); only that face of a `surface` primitive is a
support surface.

Rays: origins `o` and unit directions `d`, both (N, 3) float64 in the shape frame. Intersections
return `t` (N,) float64 metres along the ray (inf for a miss; hits closer than EPS are ignored so a
ray leaving a surface does not hit it again) and `top` (N,) bool (the hit is on the top face).
Every shape also has `contains(p, eps)` (in the material), `faces()` (area samplers),
`normals(p)` (outward, out of the material), `bounding_radius` and `half_extent` (metres).
"""

from __future__ import annotations

from supportnode.sim.primitives.base import EPS, Face, Sampler
from supportnode.sim.primitives.shells import Bowl, Cup
from supportnode.sim.primitives.solids import Box, Cone, Cylinder, Sphere
from supportnode.sim.primitives.torus import Torus

KINDS = ("box", "cylinder", "sphere", "cone", "cup", "bowl", "torus")
Shape = Box | Cylinder | Sphere | Cone | Cup | Bowl | Torus

__all__ = [
    "EPS",
    "KINDS",
    "Bowl",
    "Box",
    "Cone",
    "Cup",
    "Cylinder",
    "Face",
    "Sampler",
    "Shape",
    "Sphere",
    "Torus",
]
