#!/bin/sh
# The tables of docs/results/imu.md: RGB-D SLAM with an IMU (task slam_imu) on the synthetic room
# at 5 Hz with a simulated IMU, and on a hall rendered along the real EuRoC V1_02 flight with its
# real IMU; the relative family (prev, prev_loose …) and the absolute PoseNet (none, loose …).
# The fits of pose fields to the real gyroscope are scripts/results/trajectory.sh.
#
#   scripts/results/imu.sh [TABLE...]
#
# TABLE is synthetic, synthetic_10hz, gyro_weight, accel_tie, euroc_5hz, euroc, readings,
# bias_refine, bias_refine_room, bias_truth, velocity_start or speed (default: all, in that
# order). Runs go to runs/results/imu/NAME (common.sh: environment); a finished run is kept and
# an interrupted one resumed. The tables are printed to stdout. One EuRoC run of all eleven
# methods at 10 Hz takes about 40 minutes on one thread.
set -eu
# shellcheck source=common.sh
. "$(dirname "$0")/common.sh"
out=${CPOSE_RESULTS:-runs/results}/imu
room=configs/synthetic_imu.toml
euroc=configs/euroc_v102_imu.toml
euroc_data="euroc.path=\"$data/euroc/V1_02_excerpt\""
relative='slam.methods=["baseline","prev","prev_loose","prev_tight","prev_accel","prev_combined"]'
relative_imu='slam.methods=["prev_loose","prev_tight","prev_accel","prev_combined"]'
metrics=ate_rmse_cm,start_rpe_trans_rmse_cm,start_rpe_rot_rmse_deg,rpe_rot_rmse_deg,lost_frames,first_lost,recovered_frames

# seeds NAME CONFIG [ARGS...]: runs NAME-s0 to NAME-s3, CONFIG with ARGS and run.seed=S, and adds
# their folders to $dirs.
seeds() {
    seeds_name=$1
    seeds_config=$2
    shift 2
    for seed in 0 1 2 3; do
        run "$seeds_name-s$seed" "$seeds_config" "$@" --set "run.seed=$seed"
        dirs="$dirs $out/$seeds_name-s$seed"
    done
}

# Seeds 0 (synthetic) to 3.
table_synthetic() {
    run synthetic "$room"
    dirs="$out/synthetic"
    for seed in 1 2 3; do
        run "synthetic-s$seed" "$room" --set "run.seed=$seed"
        dirs="$dirs $out/synthetic-s$seed"
    done
    # shellcheck disable=SC2086
    table "Synthetic room at 5 Hz, simulated IMU, seeds 0–3 (configs/synthetic_imu.toml)" \
        "$metrics" $dirs
}

# The room at 10 Hz (every third frame), seeds 0 to 3, with the 5 Hz config's budgets per second:
# 10 tracking steps a frame, the map every second frame, a keyframe every second.
table_synthetic_10hz() {
    dirs=
    seeds synthetic-10hz "$room" --set data.stride=3 --set tracking.iterations=10 \
        --set mapping.every=2 --set mapping.keyframe_every=10
    # shellcheck disable=SC2086
    table "Synthetic room at 10 Hz, simulated IMU, seeds 0–3 (configs/synthetic_imu.toml)" \
        "$metrics" $dirs
}

# The gyroscope's weight at the paper's 1 (the default 10 is table synthetic).
table_gyro_weight() {
    run synthetic-gyro-weight1 "$room" --set imu.gyro_weight=1
    table "The synthetic room with the gyroscope's weight at the paper's 1 (imu.gyro_weight)" \
        "$metrics" "$out/synthetic-gyro-weight1"
}

# The relative family's accelerometer tie (imu.accel_weight; the default 0 is table synthetic).
table_accel_tie() {
    dirs=
    for weight in 1 0.1; do
        run "synthetic-accel-weight$weight" "$room" \
            --set 'slam.methods=["prev_accel","prev_combined"]' --set "imu.accel_weight=$weight"
        dirs="$dirs $out/synthetic-accel-weight$weight"
    done
    # shellcheck disable=SC2086
    table "The synthetic room with the accelerometer's tie (imu.accel_weight = 1, 0.1)" \
        "$metrics" $dirs
}

# The relative family at 5 Hz on the flight, seeds 0 (euroc-5hz) to 3, with the 10 Hz config's
# tracking budget per second of flight (80 steps a frame).
table_euroc_5hz() {
    hz5='data.stride=2'
    steps='tracking.iterations=80'
    run euroc-5hz "$euroc" --set "$euroc_data" --set "$hz5" --set "$steps" --set "$relative"
    dirs="$out/euroc-5hz"
    for seed in 1 2 3; do
        run "euroc-5hz-s$seed" "$euroc" --set "$euroc_data" --set "$hz5" --set "$steps" \
            --set "$relative" --set "run.seed=$seed"
        dirs="$dirs $out/euroc-5hz-s$seed"
    done
    # shellcheck disable=SC2086
    table "EuRoC V1_02 at 5 Hz, every second frame (configs/euroc_v102_imu.toml)" \
        "$metrics" $dirs
}

# Every method at 10 Hz, seeds 0 (euroc) to 3; vision alone (baseline, prev) also with 80
# tracking steps a frame instead of the config's 40 (euroc-80-steps).
table_euroc() {
    run euroc "$euroc" --set "$euroc_data"
    dirs="$out/euroc"
    for seed in 1 2 3; do
        run "euroc-s$seed" "$euroc" --set "$euroc_data" --set "run.seed=$seed"
        dirs="$dirs $out/euroc-s$seed"
    done
    for seed in 0 1 2 3; do
        run "euroc-80-steps-s$seed" "$euroc" --set "$euroc_data" --set "run.seed=$seed" \
            --set tracking.iterations=80 --set 'slam.methods=["baseline","prev"]'
        dirs="$dirs $out/euroc-80-steps-s$seed"
    done
    # shellcheck disable=SC2086
    table "EuRoC V1_02 at 10 Hz (configs/euroc_v102_imu.toml)" "$metrics" $dirs
}

# prev_tight at 10 Hz with the tight terms at 5 readings a step (the default) and at every
# reading (imu.max_readings=64: all 20 of a frame interval), seeds 0 to 3.
table_readings() {
    dirs=
    for readings in 5 64; do
        seeds "euroc-tight-readings$readings" "$euroc" --set "$euroc_data" \
            --set 'slam.methods=["prev_tight"]' --set "imu.max_readings=$readings"
    done
    # shellcheck disable=SC2086
    table "prev_tight at 10 Hz with 5 readings a step and with all 20 (imu.max_readings)" \
        "$metrics" $dirs
}

# The gyroscope's bias refined online (imu.bias_refine) for the relative family at 10 Hz,
# seeds 0 to 3 (the euroc table is the same without it).
table_bias_refine() {
    dirs=
    seeds euroc-bias-refine "$euroc" --set "$euroc_data" --set imu.bias_refine=true \
        --set "$relative_imu"
    # shellcheck disable=SC2086
    table "The gyroscope's bias refined online at 10 Hz (imu.bias_refine = true)" \
        "$metrics,gyro_bias_err_rad_s,gyro_bias_start_err_rad_s" $dirs
}

# The gyroscope's bias refined online on the synthetic room at 5 Hz, seeds 0 to 3 (the synthetic
# table is the same without it).
table_bias_refine_room() {
    dirs=
    seeds synthetic-bias-refine "$room" --set imu.bias_refine=true
    # shellcheck disable=SC2086
    table "The gyroscope's bias refined online on the synthetic room (imu.bias_refine = true)" \
        "$metrics,gyro_bias_err_rad_s,gyro_bias_start_err_rad_s" $dirs
}

# The control of bias_refine: the relative family at 10 Hz with the ground-truth state's bias
# removed (euroc.bias = "ground_truth", not refined), seeds 0 to 3.
table_bias_truth() {
    dirs=
    seeds euroc-bias-truth "$euroc" --set "$euroc_data" --set 'euroc.bias="ground_truth"' \
        --set imu.bias_refine=false --set "$relative_imu"
    # shellcheck disable=SC2086
    table "The ground truth's bias at 10 Hz (euroc.bias = \"ground_truth\"): the control" \
        "$metrics" $dirs
}

# The relative family without the accelerometer started at the last interval's velocity
# (imu.velocity_start = true), seeds 0 to 3: the room at 10 Hz as table synthetic_10hz, the flight
# at 10 Hz as table euroc and at 5 Hz as table euroc_5hz.
table_velocity_start() {
    dirs=
    velocity='slam.methods=["prev","prev_loose","prev_tight"]'
    seeds synthetic-10hz-velocity "$room" --set data.stride=3 --set tracking.iterations=10 \
        --set mapping.every=2 --set mapping.keyframe_every=10 --set "$velocity" \
        --set imu.velocity_start=true
    seeds euroc-velocity "$euroc" --set "$euroc_data" --set "$velocity" \
        --set imu.velocity_start=true
    seeds euroc-5hz-velocity "$euroc" --set "$euroc_data" --set data.stride=2 \
        --set tracking.iterations=80 --set "$velocity" --set imu.velocity_start=true
    # shellcheck disable=SC2086
    table "The relative family started at the last interval's velocity (imu.velocity_start)" \
        "$metrics" $dirs
}

# Each method alone on two threads at 10 Hz, seed 0: run it on an otherwise idle machine.
table_speed() {
    if [ -n "${CPOSE_THREADS:-}" ]; then
        echo "table speed skipped: it times two threads (unset CPOSE_THREADS)" >&2
        return 0
    fi
    dirs=
    for method in baseline prev prev_loose prev_tight prev_accel prev_combined none loose tight \
        accel combined; do
        run "speed/$method" "$euroc" --set "$euroc_data" --set run.threads=2 \
            --set "slam.methods=[\"$method\"]"
        dirs="$dirs $out/speed/$method"
    done
    # shellcheck disable=SC2086
    table "Speed at 10 Hz, each method alone on two threads (configs/euroc_v102_imu.toml)" \
        fps,tracking_fps,mapping_fps,ate_rmse_cm $dirs
}

tables=$(tables_from "synthetic synthetic_10hz gyro_weight accel_tie euroc_5hz euroc readings bias_refine bias_refine_room bias_truth velocity_start speed" "$@")
# shellcheck disable=SC2086 # one word per table
run_tables $tables
