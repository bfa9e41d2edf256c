#!/bin/sh
# Regenerates every committed file in sim_scans/ (deterministic: fixed seeds, byte-identical
# output). Run from the repository root:  sh sim_scans/make.sh
# Set SUPPORTNODE to another command if `python3 -m supportnode` is not the one to use.
set -eu
SN=${SUPPORTNODE:-python3 -m supportnode}
OUT=${1:-sim_scans}

# One mesh-sampled cloud per scene (noise-free, seed 0, binary PLY with ground-truth properties).
$SN sim shelf --points 150000 --seed 0 --out "$OUT/shelf_sampled.ply"
$SN sim table_chairs --points 100000 --seed 0 --out "$OUT/table_chairs_sampled.ply"
$SN sim kitchen --points 100000 --seed 0 --out "$OUT/kitchen_sampled.ply"
$SN sim u_table --points 60000 --seed 0 --out "$OUT/u_table_sampled.ply"
$SN sim sloped --points 60000 --seed 0 --out "$OUT/sloped_sampled.ply"

# Short lidar sequences along each scene's trajectory: 5 frames of an OS-128 at 10 Hz, world frame.
rm -rf "$OUT/shelf_lidar" "$OUT/table_chairs_lidar"
$SN sim shelf --sensor lidar --preset os128 --frames 5 --seed 0 --out "$OUT/shelf_lidar"
$SN sim table_chairs --sensor lidar --preset os128 --frames 5 --seed 0 --out "$OUT/table_chairs_lidar"

# The same sequences as MCAP recordings for `supportnode play` (launch/demo.yaml): PointCloud on
# topic scan in the sensor frame (frame_id lidar) with the sensor pose, stamps 0.1 s apart.
$SN record --from "$OUT/shelf_lidar" -o "$OUT/shelf_lidar.mcap" --quiet
$SN record --from "$OUT/table_chairs_lidar" -o "$OUT/table_chairs_lidar.mcap" --quiet
