#!/bin/sh
# The tables of docs/results/events.md: NeRF from colour events alone on the built-in scene on a
# turntable, with poses known at only K views (interpolation) or a mis-calibrated turntable axis
# (calibration); EventNeRF's fixed poses against PoseNet.
#
#   scripts/results/events.sh [TABLE...]
#
# TABLE is interp, calib or hold (default: all three). Runs go to runs/results/events/NAME (common.sh:
# environment); a finished run is kept and an interrupted one resumed. The tables are printed to
# stdout.
set -eu
# shellcheck source=common.sh
. "$(dirname "$0")/common.sh"
out=${CPOSE_RESULTS:-runs/results}/events

table_interp() {
    run interp configs/events_interp.toml
    # The reference at K = 6 (true poses, the same windows) and PoseNet at K = 6 without the
    # windows that end on a known view.
    run interp-true-poses configs/events_interp.toml --set 'experiment.known_poses=[6]' \
        --set 'train.methods=["true_poses"]'
    run interp-no-anchor-windows configs/events_interp.toml --set 'experiment.known_poses=[6]' \
        --set 'train.methods=["posenet"]' --set train.anchor_windows=0
    table "Poses known at K views (configs/events_interp.toml)" \
        trans_err_su,trans_err_aligned_su,rot_err_aligned_deg,rot_err_relative_deg,psnr_db,ssim,wall_s \
        "$out/interp" "$out/interp-true-poses" "$out/interp-no-anchor-windows"
}

table_calib() {
    run calib configs/events_calib.toml
    table "Turntable axis mis-calibrated (configs/events_calib.toml)" \
        rot_err_aligned_deg,rot_err_relative_deg,trans_err_aligned_su,psnr_db,ssim,wall_s "$out/calib"
}

table_hold() {
    run interp-hold10 configs/events_interp.toml --set 'experiment.known_poses=[6]' \
        --set 'train.methods=["posenet"]' --set train.pose_hold=0.1
    table "PoseNet at K = 6 with its poses held for the first 10% of the steps" \
        trans_err_su,trans_err_aligned_su,rot_err_aligned_deg,psnr_db,ssim "$out/interp-hold10"
}

tables=$(tables_from "interp calib hold" "$@")
# shellcheck disable=SC2086 # one word per table
run_tables $tables
