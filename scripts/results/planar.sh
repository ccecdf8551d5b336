#!/bin/sh
# The tables of docs/results/planar.md: the paper's 2-D image-alignment study (20 smooth rigid
# motions, PoseNet against BARF and the B-spline baseline) on the procedural texture and on the
# paper's two photographs, cat (BARF's) and girl.
#
#   scripts/results/planar.sh [TABLE...]
#
# TABLE is procedural, cat, girl or hold (default: all four). Runs go to runs/results/planar/NAME
# (common.sh: environment); a finished run is kept and an interrupted one resumed. The tables are
# printed to stdout.
set -eu
# shellcheck source=common.sh
. "$(dirname "$0")/common.sh"
out=${CPOSE_RESULTS:-runs/results}/planar
metrics=corner_err_px,corner_err_median_px,success_rate,psnr_db,wall_s

table_procedural() {
    run procedural configs/planar.toml
    table "Procedural texture (configs/planar.toml)" "$metrics" "$out/procedural"
}

table_cat() {
    run cat configs/planar_cat.toml --set "image.path=\"$data/planar/cat.jpg\""
    table "BARF's cat (configs/planar_cat.toml)" "$metrics" "$out/cat"
}

table_girl() {
    run girl configs/planar_girl.toml --set "image.path=\"$data/planar/girl.jpg\""
    table "The paper's girl photograph (configs/planar_girl.toml)" "$metrics" "$out/girl"
}

table_hold() {
    two='train.methods=["posenet","barf"]'
    run cat-hold10 configs/planar_cat.toml --set "image.path=\"$data/planar/cat.jpg\"" \
        --set "$two" --set train.pose_hold=0.1
    run girl-hold10 configs/planar_girl.toml --set "image.path=\"$data/planar/girl.jpg\"" \
        --set "$two" --set train.pose_hold=0.1
    table "Warps held for the first 10% of the steps (--set train.pose_hold=0.1)" "$metrics" \
        "$out/cat-hold10" "$out/girl-hold10"
}

tables=$(tables_from "procedural cat girl hold" "$@")
# shellcheck disable=SC2086 # one word per table
run_tables $tables
