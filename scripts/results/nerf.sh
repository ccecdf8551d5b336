#!/bin/sh
# The tables of docs/results/nerf.md: NeRF from noisy poses on the Lego orbit (the paper's noise
# grid) and with BARF's own Blender protocol, on the built-in scene (the grid, field restarts,
# the PoseNet encoding ablation), and from unknown or perturbed poses on LLFF fern.
#
#   scripts/results/nerf.sh [TABLE...]
#
# TABLE is one of hold_fern hold_synthetic lego lego_barf grid restarts restarts_grid llff
# llff_colmap encoding fields (default: all, in that order). Runs go to runs/results/nerf/GROUP/NAME
# (common.sh: environment); a finished run is kept and an interrupted one resumed, so the script
# continues where it stopped. The tables are printed to stdout. The grid is 13 runs of about 15
# minutes each on two cores; everything, about 40 runs, takes a day, so a page is usually made a
# few tables at a time (`scripts/results/page.sh nerf TABLE...` keeps the page's other tables).
set -eu
# shellcheck source=common.sh
. "$(dirname "$0")/common.sh"
out=${CPOSE_RESULTS:-runs/results}/nerf
synthetic=configs/nerf_synthetic.toml
lego=configs/nerf_lego_orbit.toml
lego_data="data.path=\"$data/nerf_synthetic/lego\""
fern=configs/llff_fern.toml
fern_data="data.path=\"$data/llff/fern\""
posenet_only='train.methods=["posenet"]'

# restarts NAME CONFIG [ARGS...]: NAME with the field-restart recipe: the field restarted every
# 750 steps up to 62.5% of them, PoseNet's rates decaying 10× instead of 100×, and its rotation
# rates ramped up over 20% of the steps. Later ARGS override the recipe.
restarts() {
    restarts_name=$1
    restarts_config=$2
    shift 2
    run "$restarts_name" "$restarts_config" \
        --set train.field_restart_every=750 --set train.field_restart_until=0.625 \
        --set 'train.posenet_lr_translation=[1e-3,1e-4]' \
        --set 'train.posenet_lr_rotation=[2e-4,2e-5]' \
        --set train.rotation_warmup=0.2 "$@"
}

# The paper's grid, name:max_rotation_deg:max_translation:posenet.translation_scale. PoseNet's
# translation head is bounded by translation_scale (2 in the config); TM 30% and 40% shift cameras
# by up to 2.4 and 3.2, so those cells raise it to 4.
cells="tm10:0:0.1:2 tm20:0:0.2:2 tm30:0:0.3:4 tm40:0:0.4:4 rm30:30:0:2 rm60:60:0:2 rm90:90:0:2
rm120:120:0:2 rm30-tm10:30:0.1:2 rm60-tm20:60:0.2:2 rm90-tm30:90:0.3:4 rm120-tm40:120:0.4:4"

# cell NAME: "ROTATION TRANSLATION SCALE" of a cell of the grid.
cell() {
    for c in $cells; do
        if [ "${c%%:*}" = "$1" ]; then
            echo "$c" | tr ':' ' ' | cut -d' ' -f2-
            return 0
        fi
    done
    echo "no cell $1" >&2
    exit 2
}

# grid_runs DIR CONFIG [ARGS...]: the true poses once, then PoseNet and BARF at every cell of
# the grid, into $out/DIR/true-poses and $out/DIR/<cell>; sets $dirs to those folders.
grid_runs() {
    grid_dir=$1
    grid_config=$2
    shift 2
    run "$grid_dir/true-poses" "$grid_config" "$@" --set 'train.methods=["true_poses"]'
    dirs="$out/$grid_dir/true-poses"
    for c in $cells; do
        name=${c%%:*}
        noise=$(cell "$name")
        r=${noise%% *}
        rest=${noise#* }
        t=${rest%% *}
        s=${rest#* }
        run "$grid_dir/$name" "$grid_config" "$@" --set 'train.methods=["posenet","barf"]' \
            --set "noise.max_rotation_deg=$r" --set "noise.max_translation=$t" \
            --set "posenet.translation_scale=$s"
        dirs="$dirs $out/$grid_dir/$name"
    done
}

grid_metrics=init_rot_err_deg,rot_err_deg,rot_err_relative_deg,trans_err_su,psnr_db,psnr_refined_db

# The pose hold (train.pose_hold), without a hold and held for 10% of the steps (until the grid's
# coarse-to-fine begins): from COLMAP's own poses on fern (a control: the poses should stay there)
# and from the default noise on the built-in scene (RM 30° + TM 10%).
table_hold_fern() {
    dirs=
    for hold in 0 0.1; do
        run "hold/fern-colmap-hold$hold" "$fern" --set "$fern_data" --set 'noise.kind="none"' \
            --set "train.pose_hold=$hold"
        dirs="$dirs $out/hold/fern-colmap-hold$hold"
    done
    # shellcheck disable=SC2086
    table "Fern from COLMAP's poses, held while the field first fits (train.pose_hold)" \
        init_rot_err_deg,rot_err_deg,rot_err_relative_deg,trans_err_su,psnr_db,psnr_refined_db \
        $dirs
}

table_hold_synthetic() {
    dirs=
    for hold in 0 0.1; do
        run "hold/synthetic-hold$hold" "$synthetic" --set 'train.methods=["posenet","barf"]' \
            --set "train.pose_hold=$hold"
        dirs="$dirs $out/hold/synthetic-hold$hold"
    done
    # shellcheck disable=SC2086
    table "The built-in scene at RM 30° + TM 10%, poses held while the field first fits" \
        init_rot_err_deg,rot_err_deg,rot_err_relative_deg,trans_err_su,psnr_db,psnr_refined_db \
        $dirs
}

table_lego() {
    grid_runs lego "$lego" --set "$lego_data"
    # shellcheck disable=SC2086
    table "The paper's noise grid on the Lego orbit (configs/nerf_lego_orbit.toml)" \
        "$grid_metrics,psnr_val_db" $dirs
}

table_lego_barf() {
    run lego_barf/lego "configs/nerf_lego_barf.toml" --set "$lego_data"
    table "BARF's Blender protocol on Lego (configs/nerf_lego_barf.toml)" \
        init_rot_err_deg,rot_err_deg,trans_err_su,psnr_db,psnr_refined_db,ssim,wall_s \
        "$out/lego_barf/lego"
}

table_grid() {
    grid_runs grid "$synthetic"
    # shellcheck disable=SC2086
    table "The paper's noise grid on the built-in scene (configs/nerf_synthetic.toml)" \
        "$grid_metrics,ssim" $dirs
}

table_restarts() {
    d=restarts
    run $d/rm60-tm10 "$synthetic" --set "$posenet_only" \
        --set noise.max_rotation_deg=60 --set noise.max_translation=0.1
    run $d/rm60-tm10-barf "$synthetic" --set 'train.methods=["barf"]' \
        --set noise.max_rotation_deg=60 --set noise.max_translation=0.1
    for seed in 0 1 2; do
        restarts "$d/rm60-tm10-restarts-s$seed" "$synthetic" --set "$posenet_only" \
            --set noise.max_rotation_deg=60 --set noise.max_translation=0.1 --set "run.seed=$seed"
    done
    restarts $d/rm60-tm20-restarts "$synthetic" --set "$posenet_only" \
        --set noise.max_rotation_deg=60 --set noise.max_translation=0.2
    table "Field restarts at RM 60° + TM 10% and 20% (PoseNet unless named)" \
        rot_err_deg,trans_err_su,psnr_db,psnr_refined_db \
        "$out/$d/rm60-tm10" "$out/$d/rm60-tm10-barf" "$out/$d/rm60-tm10-restarts-s0" \
        "$out/$d/rm60-tm10-restarts-s1" "$out/$d/rm60-tm10-restarts-s2" \
        "$out/$d/rm60-tm20-restarts"
}

table_restarts_grid() {
    dirs=
    for name in tm30 tm40 rm120 rm90-tm30 rm120-tm40; do
        # shellcheck disable=SC2046 # three words
        set -- $(cell "$name")
        restarts "restarts_grid/$name-restarts" "$synthetic" --set "$posenet_only" \
            --set "noise.max_rotation_deg=$1" --set "noise.max_translation=$2" \
            --set "posenet.translation_scale=$3"
        dirs="$dirs $out/restarts_grid/$name-restarts"
    done
    # shellcheck disable=SC2086
    table "Field restarts on the cells where PoseNet fails without them" \
        rot_err_deg,trans_err_su,psnr_db,psnr_refined_db $dirs
}

table_llff() {
    run llff/fern "$fern" --set "$fern_data"
    run llff/fern-2 "$fern" --set "$fern_data" --set data.subsample=2
    run llff/fern-4 "$fern" --set "$fern_data" --set data.subsample=4
    table "LLFF fern from unknown poses (configs/llff_fern.toml)" \
        rot_err_deg,rot_err_relative_deg,trans_err_su,psnr_db,psnr_refined_db,wall_s \
        "$out/llff/fern" "$out/llff/fern-2" "$out/llff/fern-4"
}

table_llff_colmap() {
    run llff_colmap/r0 "$fern" --set "$fern_data" --set 'noise.kind="none"' \
        --set train.iterations=3000
    dirs="$out/llff_colmap/r0"
    for r in 10 20 30 40; do
        run "llff_colmap/r$r" "$fern" --set "$fern_data" --set 'noise.kind="time_correlated"' \
            --set "noise.max_rotation_deg=$r" --set noise.max_translation=0 \
            --set noise.anchor_every=3 --set train.iterations=3000
        dirs="$dirs $out/llff_colmap/r$r"
    done
    rotation=init_rot_err_deg,init_rot_err_relative_deg,rot_err_deg,rot_err_relative_deg
    # shellcheck disable=SC2086
    table "LLFF fern from COLMAP's poses turned by up to R degrees" \
        "$rotation,trans_err_su,psnr_refined_db" $dirs
}

table_encoding() {
    d=encoding
    run $d/linear-coupled "$synthetic" --set "$posenet_only" \
        --set 'posenet.encoding="linear"' --set posenet.coupled=true
    for bands in 2 5 10; do
        run "$d/f$bands-coupled" "$synthetic" --set "$posenet_only" \
            --set "posenet.bands=$bands" --set posenet.coupled=true
        run "$d/f$bands" "$synthetic" --set "$posenet_only" --set "posenet.bands=$bands"
    done
    run $d/sigmoid "$synthetic" --set "$posenet_only" --set 'posenet.activation="sigmoid"'
    run $d/f10-c2f "$synthetic" --set "$posenet_only" --set posenet.bands=10 \
        --set 'posenet.c2f=[0.1,0.5]'
    table "PoseNet's encoding at RM 30° + TM 10% (configs/nerf_synthetic.toml)" \
        rot_err_deg,trans_err_su,psnr_db,psnr_refined_db \
        "$out/$d/linear-coupled" "$out/$d/f2-coupled" "$out/$d/f5-coupled" \
        "$out/$d/f10-coupled" "$out/$d/f2" "$out/$d/f5" "$out/$d/f10" "$out/$d/sigmoid" \
        "$out/$d/f10-c2f"
}

# The two radiance fields with the true poses, 1500 steps each: the hash grid (the default) and
# BARF's NeRF MLP at half its depth and width (4 layers of 128, the input again at the third).
table_fields() {
    true_poses='train.methods=["true_poses"]'
    run fields/grid "$synthetic" --set "$true_poses" --set train.iterations=1500
    run fields/mlp "$synthetic" --set "$true_poses" --set train.iterations=1500 \
        --set 'field.kind="mlp"' --set field.depth=4 --set field.width=128 \
        --set field.skip_layer=2
    table "The radiance fields with the true poses, 1500 steps (configs/nerf_synthetic.toml)" \
        final_loss,psnr_db,ssim,wall_s "$out/fields/grid" "$out/fields/mlp"
}

tables=$(tables_from "hold_fern hold_synthetic lego lego_barf grid restarts restarts_grid llff llff_colmap encoding fields" "$@")
# shellcheck disable=SC2086 # one word per table
run_tables $tables
