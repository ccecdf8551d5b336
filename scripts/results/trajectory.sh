#!/bin/sh
# The tables of docs/results/trajectory.md: pose fields fitted to sparse poses, with and without
# the gyroscope, scored on the held-out poses: the built-in synthetic motion and 20 s of the real
# EuRoC V1_02 flight; PoseNet's frequency bands against the pose spacing.
#
#   scripts/results/trajectory.sh [TABLE...]
#
# TABLE is synthetic, euroc_estimate, euroc, bands or patience (default: all five). Runs go to
# runs/results/trajectory/NAME (common.sh: environment); a finished run is kept and an
# interrupted one resumed. The tables are printed to stdout.
set -eu
# shellcheck source=common.sh
. "$(dirname "$0")/common.sh"
out=${CPOSE_RESULTS:-runs/results}/trajectory
metrics=rot_err_deg,rot_rmse_deg,trans_err_m,ang_vel_rmse_rad_s,known_rot_err_deg,fit_steps,fit_stop
euroc_data="data.path=\"$data/euroc/V1_02_excerpt\""

table_synthetic() {
    run synthetic configs/trajectory_fit.toml
    table "Built-in synthetic motion, every 20th pose (configs/trajectory_fit.toml)" \
        "$metrics" "$out/synthetic"
}

# The gyroscope's bias: estimated over the flight's stationary start (the config's default), and
# the ground-truth state's (an ablation; the tables before the estimate existed used it).
gt_bias='data.bias="ground_truth"'

table_euroc_estimate() {
    run euroc-estimate configs/euroc_v102_fit.toml --set "$euroc_data"
    table "EuRoC V1_02, every 20th pose, real gyroscope, bias estimated at rest (configs/euroc_v102_fit.toml)" \
        "$metrics" "$out/euroc-estimate"
}

table_euroc() {
    run euroc configs/euroc_v102_fit.toml --set "$euroc_data" --set "$gt_bias"
    table "EuRoC V1_02, every 20th pose, real gyroscope, the ground truth's bias (--set data.bias='\"ground_truth\"')" \
        "$metrics" "$out/euroc"
}

table_bands() {
    dirs=
    for bands in 2 3 4 5 6; do
        only='fit.fields=["posenet"]'
        run "bands/synthetic-f$bands" configs/trajectory_fit.toml --set "$only" \
            --set 'fit.imu=["none"]' --set "fields.posenet.bands=$bands"
        run "bands/euroc-f$bands" configs/euroc_v102_fit.toml --set "$euroc_data" \
            --set "$only" --set 'fit.imu=["none"]' --set "fields.posenet.bands=$bands"
        dirs="$dirs $out/bands/synthetic-f$bands $out/bands/euroc-f$bands"
    done
    # shellcheck disable=SC2086
    table "PoseNet's bands F, poses only (synthetic: every 0.2 s of 10 s; EuRoC: every 0.5 s of 20 s)" \
        rot_err_deg,trans_err_m,known_rot_err_deg,known_trans_err_m,fit_steps,fit_stop $dirs
}

table_patience() {
    # Loose PoseNet on EuRoC with plateaus of 4000 steps and three rate drops (default 1000, two).
    run euroc-loose-patience configs/euroc_v102_fit.toml --set "$euroc_data" \
        --set 'fit.fields=["posenet"]' --set 'fit.imu=["loose"]' --set fit.plateau_steps=4000 \
        --set fit.lr_drops=3 --set "$gt_bias"
    table "Loose PoseNet on EuRoC with more patience (--set fit.plateau_steps=4000 --set fit.lr_drops=3)" \
        "$metrics" "$out/euroc-loose-patience"
}

tables=$(tables_from "synthetic euroc_estimate euroc bands patience" "$@")
# shellcheck disable=SC2086 # one word per table
run_tables $tables
