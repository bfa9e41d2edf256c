"""No dead keys: every key of ``config/default.yaml`` changes what the detection or the node does.

A detection key is shown by running the pipeline on a small simulated scene with the default
and with one changed value (in the context it needs: ``knn`` keys under ``objects.method: knn``)
and finding a different labelling or safe list. A node key is shown by a named test that sets it
and checks the behaviour it governs; the test must exist and name the key. A key added to the
configuration without either fails here, as does a probe left for a removed key.
"""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path

import numpy as np
import pytest
import yaml

from supportnode.config import load_config
from supportnode.detection.policy import is_safe
from supportnode.pipeline import detect
from supportnode.sim import load_scene
from supportnode.sim.noise import parse_noise
from supportnode.sim.sensors import DepthCamera
from supportnode.sim.simulate import sampled, scans
from supportnode.sim.trajectory import poses_for

ROOT = Path(__file__).resolve().parents[2]
DEFAULT = ROOT / "config" / "default.yaml"

# key -> (scene[@points], changed value, context settings, align)
DETECTION_PROBES: dict[str, tuple[str, str, tuple[str, ...], bool]] = {
    "surfaces.method": ("kitchen", "seed", (), False),
    "surfaces.plane_voxel": ("kitchen", "[0.2, 0.2, 0.1]", (), False),
    "surfaces.p_min": ("kitchen", "8", (), False),
    "surfaces.psi_min": ("kitchen", "40", ("surfaces.method=seed",), False),
    "surfaces.connectivity": ("kitchen", "4", ("surfaces.method=seed",), False),
    "surfaces.max_tilt_deg": ("kitchen", "40.0", (), False),
    "surfaces.max_roughness": ("kitchen", "0.048", (), False),
    "surfaces.max_step": ("kitchen", "0.12", (), False),
    "surfaces.min_area": ("kitchen", "0.32", (), False),
    "surfaces.min_width": ("kitchen", "0.6", (), False),
    "surfaces.point_tolerance": ("kitchen", "0.04", (), False),
    "surfaces.bridge_cells": ("kitchen", "4", (), False),
    "surfaces.absorb_steps": ("kitchen", "0", (), False),
    "surfaces.absorb_min_fraction": ("kitchen", "0.8", (), False),
    "surfaces.clutter_normal_k": ("kitchen", "40", (), False),
    "surfaces.normal_filter": ("kitchen", "true", (), False),
    "surfaces.normal_filter_k": ("kitchen", "5", ("surfaces.normal_filter=true",), False),
    "surfaces.normal_filter_max_tilt_deg": ("kitchen", "80.0", (), False),
    "surfaces.object_top_max_area": ("kitchen", "0.0", (), False),
    "surfaces.object_top_max_height": ("kitchen", "0.125", (), False),
    "surfaces.plateau_min_step": ("kitchen", "0.048", (), False),
    "surfaces.plateau_max_area": ("kitchen", "0.0", (), False),
    "objects.method": ("kitchen", "knn", (), False),
    "objects.k": ("shelf", "5", ("objects.method=knn",), False),
    "objects.sample_fraction": ("kitchen", "0.075", ("objects.method=knn",), False),
    "objects.seed": ("kitchen", "3", ("objects.method=knn",), False),
    "objects.label_radius": ("kitchen", "0.2", ("objects.method=knn",), False),
    "objects.cluster_cell": ("kitchen", "0.12", (), False),
    "objects.min_points": ("kitchen", "120", (), False),
    "objects.support_tolerance": ("kitchen", "0.2", (), False),
    "objects.split_touching": ("u_table@100000", "false", (), False),
    "objects.split_neck_width": ("kitchen", "0.01", (), False),
    "objects.split_concave": ("shelf@539034", "true", (), False),  # dense: the report's shelf
    "objects.concave_tolerance": ("shelf@539034", "0.002", ("objects.split_concave=true",), False),
    # The convex method's faces and the noise band act on a depth camera's dense view.
    "objects.convex_cell": ("cluttered_table@kinect", "0.02", (), False),
    "objects.convex_normal_cells": ("cluttered_table@kinect", "4", (), False),
    "objects.convex_smooth_deg": ("cluttered_table@kinect", "89.0", (), False),
    "objects.foot_reach": ("cluttered_table@kinect", "0.0", (), False),
    "surfaces.band_sigmas": ("cluttered_table@kinect", "0.0", (), False),
    "surfaces.band_min": ("cluttered_table@kinect", "0.008", (), False),
    "freespace.cell_size": ("kitchen", "0.08", (), False),
    "freespace.margin": ("kitchen", "0.2", (), False),
    "gravity.up_hint": ("kitchen", "[1.0, 0.0, 0.0]", (), True),
    "gravity.hint_cone_deg": ("kitchen", "5", ("gravity.up_hint=[0.3, 0, 1]",), True),
    "gravity.downsample_voxel": ("table_chairs", "0.2", (), True),
    "gravity.inlier_angle_deg": ("kitchen", "40.0", (), True),
    "safe.min_area": ("kitchen", "5.0", (), False),
    "safe.max_flatness": ("kitchen", "0.0001", (), False),
    "safe.max_tilt_deg": ("kitchen", "0.0", (), False),
}

# key -> "tests/file.py::test_name": a test that sets the key and checks what it governs.
NODE_EVIDENCE: dict[str, str] = {
    "gravity.enabled": "tests/node/test_node.py::test_gravity_estimated_without_imu_levels_results",
    "node.name": "tests/node/test_node_keys.py::test_name_and_frame_id_are_what_results_and_diagnostics_say",
    "node.frame_id": "tests/node/test_node_keys.py::test_name_and_frame_id_are_what_results_and_diagnostics_say",
    "node.scan_endpoint": "tests/node/test_node_core.py::test_published_results_equal_node_process",
    "node.pub_endpoint": "tests/node/test_node_core.py::test_published_results_equal_node_process",
    "node.scan_bind": "tests/test_curve.py::test_node_binding_for_scans_takes_drivers_from_their_folder",
    "node.pub_bind": "tests/node/test_node_keys.py::test_pub_bind_false_connects_to_a_forwarder_and_diagnostics_period_paces_it",
    "node.diagnostics_period": "tests/node/test_node_keys.py::test_pub_bind_false_connects_to_a_forwarder_and_diagnostics_period_paces_it",
    "node.scan_topic": "tests/node/test_node_keys.py::test_topic_names_are_the_configured_ones",
    "node.surfaces_topic": "tests/node/test_node_keys.py::test_topic_names_are_the_configured_ones",
    "node.obstacles_topic": "tests/node/test_node_keys.py::test_topic_names_are_the_configured_ones",
    "node.diagnostics_topic": "tests/node/test_node_keys.py::test_topic_names_are_the_configured_ones",
    "node.map_topic": "tests/node/test_node_keys.py::test_topic_names_are_the_configured_ones",
    "node.map_period": "tests/node/test_node_keys.py::test_topic_names_are_the_configured_ones",
    "node.detection_rate": "tests/node/test_node.py::test_detection_rate_skips_scans_but_keeps_the_map",
    "node.threads": "tests/node/test_node_diagnostics_race.py::test_rejects_from_two_threads_while_diagnostics_are_made",
    "node.safe_min_hits": "tests/node/test_node.py::test_safe_rule_is_configuration",
    "node.max_points": "tests/node/test_node.py::test_too_many_points_rejected",
    "node.max_message_bytes": "tests/test_bus.py::test_oversized_messages_are_discarded",
    "node.reject_log_period": "tests/node/test_node_keys.py::test_reject_log_period_rate_limits_the_reject_lines",
    "node.max_stamp_jump": "tests/node/test_intake.py::test_stamp_gate",
    "node.gravity_max_angle_deg": "tests/node/test_node_keys.py::test_gravity_max_angle_decides_what_is_an_outlier",
    "node.gravity_min_agreeing": "tests/node/test_node_keys.py::test_gravity_min_agreeing_is_the_vote_before_adopting",
    "node.map.radius": "tests/node/test_node_keys.py::test_map_voxel_size_and_radius_shape_the_map",
    "node.map.voxel_size": "tests/node/test_node_keys.py::test_map_voxel_size_and_radius_shape_the_map",
    "node.map.max_age": "tests/map/test_map.py::test_crop_radius_age_and_cap",
    "node.map.max_voxels": "tests/map/test_map.py::test_crop_radius_age_and_cap",
    "node.map.clear_free_space": "tests/map/test_map.py::test_crop_radius_age_and_cap",
    "node.curve_enabled": "tests/test_curve.py::test_node_publishes_only_to_authorised_clients",
    "node.curve_keys_dir": "tests/test_curve.py::test_node_publishes_only_to_authorised_clients",
}

# keys whose effect needs more than a small scene, shown by the named test instead
DETECTION_EVIDENCE: dict[str, str] = {}


def _leaves(tree: dict, prefix: str = "") -> list[str]:
    out = []
    for key, value in tree.items():
        if isinstance(value, dict):
            out += _leaves(value, f"{prefix}{key}.")
        else:
            out.append(prefix + key)
    return out


KEYS = _leaves(yaml.safe_load(DEFAULT.read_text(encoding="utf-8")))


def test_every_key_is_shown_to_matter() -> None:
    shown = set(DETECTION_PROBES) | set(NODE_EVIDENCE) | set(DETECTION_EVIDENCE)
    assert not set(KEYS) - shown, f"keys nothing shows to matter: {sorted(set(KEYS) - shown)}"
    assert not shown - set(KEYS), (
        f"probes for keys the configuration lacks: {sorted(shown - set(KEYS))}"
    )


@cache
def _cloud(scene: str) -> tuple[np.ndarray, np.ndarray | None]:
    """A bundled scene sampled by area: "NAME" (40,000 points) or "NAME@POINTS"; or seen by
    a Kinect with its noise, "NAME@kinect". Points (N, 3) and the sensor's position."""
    name, _, points = scene.partition("@")
    if points == "kinect":
        s = load_scene(name)
        camera = DepthCamera.preset("kinect")
        view = scans(s, camera, poses_for(s, 1, level=False), 0, parse_noise(["kinect"]))[0]
        return view.points.astype(np.float64), view.sensor_pose[:3, 3]
    cloud = sampled(load_scene(name), int(points or 40_000), seed=0)
    return cloud.points.astype(np.float64), None


def _signature(scene: str, settings: tuple[str, ...], align: bool) -> tuple:
    params = load_config(None, settings)
    pts, origin = _cloud(scene)
    det = detect(pts, params, align=align, sensor_origin=origin)
    safe = tuple(is_safe(s, params.safe) for s in det.surfaces.surfaces)
    free = tuple(round(f.free_area, 6) for f in det.free_space)
    objects = det.objects.labels.tobytes() if det.objects is not None else b""
    return det.surfaces.labels.tobytes(), objects, safe, free


@pytest.mark.parametrize("key", sorted(DETECTION_PROBES))
def test_detection_key_changes_the_result(key: str) -> None:
    scene, value, context, align = DETECTION_PROBES[key]
    default = _signature(scene, context, align)
    assert _signature(scene, (*context, f"{key}={value}"), align) != default, (
        f"{key}={value} changed nothing on {scene}"
    )


@pytest.mark.parametrize("key", sorted({**NODE_EVIDENCE, **DETECTION_EVIDENCE}))
def test_key_evidence_is_a_test_that_sets_it(key: str) -> None:
    where = {**NODE_EVIDENCE, **DETECTION_EVIDENCE}[key]
    path, name = where.split("::")
    tree = ast.parse((ROOT / path).read_text(encoding="utf-8"))
    funcs = {f.name: f for f in ast.walk(tree) if isinstance(f, ast.FunctionDef)}
    assert name in funcs, f"{where} does not exist"
    # the key is set in the test itself or in a helper of its file (a node fixture)
    assert key.rsplit(".", 1)[-1] in ast.unparse(tree), f"{path} does not set {key}"
