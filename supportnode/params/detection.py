"""Parameters of the detection: surfaces, objects, free space, gravity alignment, the safe rule.

One frozen dataclass per stage; each is a section of the configuration (see `supportnode.params`).
"""

from __future__ import annotations

from dataclasses import dataclass

from supportnode.params.base import param


@dataclass(frozen=True)
class SurfaceParams:
    """Support-surface detection (Algorithm 1 of the report and the planar default)."""

    method: str = param(
        "planar",
        "'seed': the report's Algorithm 1 as published; 'planar': per-voxel plane fits, "
        "growth across height layers, area and width limits",
        choices=("seed", "planar"),
    )
    plane_voxel: tuple[float, float, float] = param(
        (0.1, 0.1, 0.05),
        "edge lengths vx, vy, vz of the voxels surfaces are built from (seed: occupied voxels "
        "grown into regions; planar: one plane fit per voxel); a surface's footprint cells are "
        "vx by vy",
        "m",
        min=1e-3,
        max=10.0,
    )
    p_min: int = param(2, "a voxel counts only if it holds MORE than p_min points", min=0)
    psi_min: int = param(
        10, "seed method: a region is a surface only with at least psi_min voxels", min=1
    )
    connectivity: int = param(
        8, "horizontal neighbourhood for region growing: 4 or 8", choices=(4, 8)
    )
    max_tilt_deg: float = param(
        10.0,
        "planar: a voxel's fitted normal may deviate from +z by at most this",
        "deg",
        min=0.0,
        max=89.0,
    )
    max_roughness: float = param(
        0.012, "planar: largest rms distance of a voxel's points to its plane", "m", min=0.0
    )
    max_step: float = param(
        0.03,
        "planar: largest height change between adjacent voxels of one surface",
        "m",
        min=0.0,
    )
    min_area: float = param(0.08, "planar: smallest surface footprint area", "m^2", min=0.0)
    min_width: float = param(
        0.15,
        "planar: narrowest a surface may be (a rail or wall top is not a surface)",
        "m",
        min=0.0,
    )
    point_tolerance: float = param(
        0.01,
        "planar: a point is on a surface if this close to the surface's local plane "
        "(widened to 3x the surface's median voxel roughness on noisy clouds); a depth "
        "camera's surfaces use their noise band instead (band_sigmas), at most this wide",
        "m",
        min=0.0,
    )
    band_sigmas: float = param(
        3.5,
        "planar: a point is on a surface within this many sigma of its plane, sigma the "
        "surface's own noise at the point's range (measured on it; 0: point_tolerance alone)",
        min=0.0,
    )
    band_min: float = param(
        0.003,
        "planar: the noise band is never thinner than this (noise-free clouds)",
        "m",
        min=0.0,
    )
    bridge_cells: int = param(
        1,
        "planar: empty cells a surface may span between level voxels of the same plane "
        "(gaps between a lidar's rings far away); 0: only adjacent voxels join",
        min=0,
        max=5,
    )
    absorb_steps: int = param(
        4,
        "planar: rings of cluttered voxels (a board's edge by a panel, the foot of an "
        "object) a surface may grow into when part of their points lie on its plane",
        min=0,
        max=50,
    )
    absorb_min_fraction: float = param(
        0.2,
        "planar: share of a cluttered voxel's points that must lie on the plane for it to join",
        min=0.0,
        max=1.0,
    )
    clutter_normal_k: int = param(
        10,
        "planar: neighbours for the normals that vet surface points in cluttered voxels "
        "(tilted by more than normal_filter_max_tilt_deg: not on the surface); 0: no vetting",
        min=0,
        max=100,
    )
    normal_filter: bool = param(
        False,
        "the report's option: drop points whose k-NN normal is not vertical before "
        "growing (only candidate points are tested)",
    )
    normal_filter_k: int = param(30, "neighbours for the normal filter", min=3, max=500)
    normal_filter_max_tilt_deg: float = param(
        20.0,
        "normal filter: largest angle between a point normal and +z",
        "deg",
        min=0.0,
        max=90.0,
    )
    object_top_max_area: float = param(
        0.5,
        "planar: a level face smaller than this that stands on a lower surface which is "
        "hidden under it (the top of a box on a worktop) and holds nothing is an object's "
        "top, not a surface; 0: off",
        "m^2",
        min=0.0,
    )
    object_top_max_height: float = param(
        0.5,
        "planar: such a face is an object's top only this close above the surface around it",
        "m",
        min=0.0,
    )
    plateau_min_step: float = param(
        0.012,
        "planar: a part of a surface that rises by a step at least this high (and at least "
        "the point tolerance) above the rest around it is a flat object lying on it (a "
        "cutting board, a plate), not surface; smooth slopes and warps are no steps; 0: off",
        "m",
        min=0.0,
    )
    plateau_max_area: float = param(
        0.3,
        "planar: such a raised part is an object only up to this footprint area",
        "m^2",
        min=0.0,
    )


@dataclass(frozen=True)
class ObjectParams:
    """Supported-object segmentation (Algorithm 2 of the report and the voxel default)."""

    method: str = param(
        "convex",
        "'knn': the report's Algorithm 2 (sampled k-NN graph); 'voxel': connected "
        "occupied voxels of a fine grid, no sampling; 'convex': as voxel, then the densely "
        "sampled groups (a depth camera's) split into smooth faces joined where they meet "
        "convexly, cut at concave creases (touching and stacked objects)",
        choices=("knn", "voxel", "convex"),
    )
    k: int = param(20, "knn: neighbours linked per sampled point", min=1, max=500)
    sample_fraction: float = param(
        0.3, "knn: fraction s of the non-surface points sampled", min=1e-4, max=1.0
    )
    seed: int = param(0, "random seed for sampling", min=0)
    label_radius: float = param(
        0.05,
        "knn: unsampled points take the label of the nearest sampled point within this",
        "m",
        min=0.0,
    )
    cluster_cell: float = param(
        0.03,
        "voxel: occupied cells of this edge that touch (26-neighbours) are one cluster; "
        "splitting touching objects rasters their footprints at a third of it, their tops and "
        "creases at it",
        "m",
        min=1e-3,
        max=1.0,
    )
    min_points: int = param(30, "smallest cluster kept (smaller ones are noise)", min=1)
    support_tolerance: float = param(
        0.05,
        "a cluster stands on a surface when its lowest points are this close above it",
        "m",
        min=0.0,
    )
    split_touching: bool = param(
        True, "split clusters whose footprint has separate parts joined by a thin neck"
    )
    split_neck_width: float = param(
        0.04, "footprint necks narrower than this separate two objects", "m", min=0.0
    )
    split_concave: bool = param(
        False,
        "split clusters that fall apart into parts standing side by side on the surface when "
        "the voxels along concave creases are removed (touching convex objects)",
    )
    convex_cell: float = param(
        0.005,
        "convex: points in 26-adjacent cells this wide are linked (wider gaps cut); grown "
        "until a typical cell holds a few points (sparse clouds, maps)",
        "m",
        min=1e-3,
        max=0.1,
    )
    convex_normal_cells: int = param(
        2,
        "convex: a cell's normal comes from the cells within this many cells of it (a "
        "depth camera's noise and depth steps scatter a one-cell normal)",
        min=1,
        max=6,
    )
    convex_smooth_deg: float = param(
        25.0,
        "convex: faces whose normals differ by less than this stay joined where they meet "
        "concavely (a bowl's inside)",
        "deg",
        min=0.0,
        max=90.0,
    )
    foot_reach: float = param(
        0.015,
        "the points of a surface's noise band under an object go to the object where the "
        "object comes down to within this of the surface over them (its foot); 0: none",
        "m",
        min=0.0,
    )
    concave_tolerance: float = param(
        0.1,
        "a link between neighbouring voxels is concave when their normals converge by more "
        "than this (normal difference along the centroid offset, per unit offset)",
        min=0.0,
        max=2.0,
    )


@dataclass(frozen=True)
class FreeSpaceParams:
    """Free (unoccupied) part of each support surface."""

    cell_size: float = param(0.02, "2-D grid cell for the free-space map", "m", min=1e-3)
    margin: float = param(0.05, "clearance kept around each object footprint", "m", min=0.0)


@dataclass(frozen=True)
class GravityParams:
    """Gravity alignment when no IMU gives the up direction."""

    enabled: bool = param(False, "estimate the rotation to gravity from normals")
    up_hint: tuple[float, float, float] = param(
        (0.0, 0.0, 0.0),
        "approximate up vector in the cloud frame (the plane family nearest it is up, never "
        "a refusal); zeros: decide from the scene",
    )
    hint_cone_deg: float = param(
        60.0,
        "up_hint: plane families within this angle of it compete (the nearest wins); none: "
        "up is refined on the planar normals within it, or is the hint itself",
        "deg",
        min=1.0,
        max=90.0,
    )
    downsample_voxel: float = param(
        0.05,
        "the cloud is thinned to one point per voxel of this edge before its normals are "
        "estimated (counts of normals are then areas); also the height bin that tells parallel "
        "planes apart",
        "m",
        min=1e-3,
    )
    inlier_angle_deg: float = param(
        10.0, "normals within this of the up direction refine it", "deg", min=0.1, max=45.0
    )


@dataclass(frozen=True)
class SafeParams:
    """When a surface is ``safe`` for a planner to put something down on (all must hold)."""

    min_area: float = param(0.10, "smallest footprint area", "m^2", min=0.0)
    max_flatness: float = param(
        0.01, "largest rms distance of its points to its plane", "m", min=0.0
    )
    max_tilt_deg: float = param(
        5.0, "largest angle between its normal and up", "deg", min=0.0, max=90.0
    )
