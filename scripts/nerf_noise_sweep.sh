#!/bin/sh
# The paper's interpolated pose-noise grid (supplement, "Interpolated pose noise experiments"):
# translation only (TM 10–40 % of the orbit diameter), rotation only (RM 30–120°) and both, on
# configs/nerf_synthetic.toml with PoseNet and BARF, one run with the true poses (the PSNR
# reference, the same for every case), then one table of all runs.
#
#   scripts/nerf_noise_sweep.sh [OUT_DIR] [--set key=value]...
#
# OUT_DIR defaults to runs/nerf-noise-sweep. Extra arguments go to every `cpose run` (e.g.
# `--set train.iterations=3000`). A case whose folder already holds metrics.json is skipped, so
# an interrupted sweep continues where it stopped. Twelve cases of two methods take hours on two
# cores; the table is written to OUT_DIR/table.md.
set -eu

out=${1:-runs/nerf-noise-sweep}
[ $# -gt 0 ] && shift
cpose=${CPOSE:-target/release/cpose}
[ -x "$cpose" ] || cargo build --release -p cpose-cli
mkdir -p "$out"

run() {
    [ -f "$out/$1/metrics.json" ] && return
    name=$1
    shift
    "$cpose" run configs/nerf_synthetic.toml --out "$out/$name" --force --quiet "$@"
}

run true-poses --set 'train.methods=["true_poses"]' "$@"
# name:max_rotation_deg:max_translation:posenet.translation_scale. PoseNet's translation head is
# bounded by translation_scale (2 in the config); TM 30 % and 40 % shift cameras by up to 2.4 and
# 3.2, so those cells raise it to 4.
for case in tm10:0:0.1:2 tm20:0:0.2:2 tm30:0:0.3:4 tm40:0:0.4:4 \
    rm30:30:0:2 rm60:60:0:2 rm90:90:0:2 rm120:120:0:2 \
    rm30-tm10:30:0.1:2 rm60-tm20:60:0.2:2 rm90-tm30:90:0.3:4 rm120-tm40:120:0.4:4; do
    name=${case%%:*}
    rest=${case#*:}
    rotation=${rest%%:*}
    rest=${rest#*:}
    run "$name" --set 'train.methods=["posenet","barf"]' --set noise.max_rotation_deg="$rotation" \
        --set noise.max_translation="${rest%%:*}" --set posenet.translation_scale="${rest#*:}" "$@"
done

"$cpose" table "$out"/*/ --metrics init_rot_err_deg,rot_err_deg,init_trans_err,trans_err,psnr_db,ssim,psnr_db_refined \
    | tee "$out/table.md"
