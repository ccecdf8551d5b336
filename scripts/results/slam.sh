#!/bin/sh
# The tables of docs/results/slam.md: RGB-D neural SLAM on the synthetic room, along the built-in
# hand-held walk and along the real TUM fr1/xyz motion; NICE-SLAM's free pose against PoseNet
# relative to the previous camera, the first camera and a random reference, and the intrinsic
# motion frame.
#
#   scripts/results/slam.sh [TABLE...]
#
# TABLE is methods, network, rates, redkitchen, budget or intrinsic (default: all six). Runs go to
# runs/results/slam/NAME (common.sh: environment); a finished run is kept and an interrupted one
# resumed. The tables are printed to stdout. The rooms are generated on first use into
# data/synthetic_room and data/synthetic_room_fr1xyz.
set -eu
# shellcheck source=common.sh
. "$(dirname "$0")/common.sh"
out=${CPOSE_RESULTS:-runs/results}/slam
config=configs/synthetic_room.toml
fr1xyz_motion="synthetic.trajectory=\"$data/tum/fr1_xyz/groundtruth.txt\""
fr1xyz_room=data.path=data/synthetic_room_fr1xyz
two='slam.methods=["baseline","prev"]'

table_methods() {
    run walk "$config"
    run fr1xyz "$config" --set "$fr1xyz_motion" --set "$fr1xyz_room"
    mesh=mesh_accuracy_cm,mesh_completion
    table "Tracking methods (configs/synthetic_room.toml)" \
        "ate_rmse_cm,ate_max_cm,drift_rmse_cm,first_lost,lost_frames,$mesh,dof_motion,fps" \
        "$out/walk" "$out/fr1xyz"
}

table_network() {
    # The paper's tracking PoseNet (8×256, the default; in `methods`) against 4×128.
    small='posenet.network.depth=4'
    run walk-4x128 "$config" --set 'slam.methods=["prev"]' --set "$small" \
        --set posenet.network.width=128 --set posenet.network.skip_layer=2
    run fr1xyz-4x128 "$config" --set 'slam.methods=["prev"]' --set "$fr1xyz_motion" \
        --set "$fr1xyz_room" --set "$small" --set posenet.network.width=128 \
        --set posenet.network.skip_layer=2
    table "The tracking PoseNet at 4×128 (prev; 8×256 is in the methods table)" \
        ate_rmse_cm,ate_max_cm,first_lost,fps "$out/walk-4x128" "$out/fr1xyz-4x128"
}

table_rates() {
    # PoseNet's own rates (prev, the first 200 frames of the walk): translation × rotation; the
    # free pose on the same frames for reference.
    run rates/walk200-baseline "$config" --set 'slam.methods=["baseline"]' --set data.frames=200
    dirs=$out/rates/walk200-baseline
    for t in 5e-4 1e-3 2e-3; do
        for r in 2.5e-4 5e-4 1e-3; do
            run "rates/walk200-t$t-r$r" "$config" --set 'slam.methods=["prev"]' \
                --set data.frames=200 --set "posenet.lr_translation=$t" \
                --set "posenet.lr_rotation=$r"
            dirs="$dirs $out/rates/walk200-t$t-r$r"
        done
    done
    # shellcheck disable=SC2086
    table "PoseNet's learning rates (prev, first 200 frames of the walk; lr_translation, lr_rotation)" \
        ate_rmse_cm,ate_max_cm,first_lost $dirs
}

table_redkitchen() {
    run redkitchen configs/7scenes_redkitchen.toml \
        --set "data.path=\"$data/7scenes/redkitchen_0000_0499\""
    table "Real Kinect frames: 7-Scenes redkitchen 0–499 at 320×240 (configs/7scenes_redkitchen.toml)" \
        ate_rmse_cm,drift_rmse_cm,rpe_trans_rmse_cm,rpe_rot_rmse_deg,first_lost,mesh_accuracy_cm,mesh_completion,fps,tracking_fps,mapping_fps,cpu_s \
        "$out/redkitchen"
}

table_budget() {
    # NICE-SLAM's Replica budget: 10 steps of 200 pixels per frame (the config: 20 of 400).
    run walk-nice-budget "$config" --set "$two" \
        --set tracking.iterations=10 --set tracking.pixels=200
    run fr1xyz-nice-budget "$config" --set "$two" --set "$fr1xyz_motion" --set "$fr1xyz_room" \
        --set tracking.iterations=10 --set tracking.pixels=200
    # 40 steps with the rates of the authors' PoseNet tracking.
    run walk-40-steps "$config" --set "$two" --set tracking.iterations=40 \
        --set posenet.lr_translation=2e-3 --set posenet.lr_rotation=4e-4
    table "Tracking budgets (free pose and prev)" ate_rmse_cm,first_lost,fps \
        "$out/walk-nice-budget" "$out/fr1xyz-nice-budget" "$out/walk-40-steps"
}

table_intrinsic() {
    intrinsic='slam.methods=["intrinsic"]'
    run walk-dof-weight-1 "$config" --set "$intrinsic" --set intrinsic.dof_weight=1
    run walk-dof-weight-10 "$config" --set "$intrinsic" --set intrinsic.dof_weight=10
    run walk-product "$config" --set "$intrinsic" --set 'intrinsic.composition="product"'
    run fr1xyz-product "$config" --set "$intrinsic" --set "$fr1xyz_motion" \
        --set "$fr1xyz_room" --set 'intrinsic.composition="product"'
    table "The intrinsic frame's DOF weight and composition" \
        ate_rmse_cm,first_lost,dof_motion,dof_intrinsic \
        "$out/walk-dof-weight-1" "$out/walk-dof-weight-10" "$out/walk-product" \
        "$out/fr1xyz-product"
}

tables=$(tables_from "methods network rates redkitchen budget intrinsic" "$@")
# shellcheck disable=SC2086 # one word per table
run_tables $tables
