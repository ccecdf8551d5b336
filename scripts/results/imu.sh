#!/bin/sh
# The tables of docs/results/imu.md: RGB-D SLAM with an IMU (task slam_imu) on the synthetic room
# at 5 Hz with a simulated IMU, and on a hall rendered along the real EuRoC V1_02 flight with its
# real IMU; the relative family (prev, prev_loose …) and the absolute PoseNet (none, loose …).
# The fits of pose fields to the real gyroscope are scripts/results/trajectory.sh.
#
#   scripts/results/imu.sh [TABLE...]
#
# TABLE is synthetic, gyro_weight, accel_tie, euroc_5hz, euroc or windows_gyro (default: all, in
# that order).
# Runs go to runs/results/imu/NAME (common.sh: environment); a finished run is kept and an
# interrupted one resumed. The tables are printed to stdout. One EuRoC run of all eleven methods
# takes about 1.5 hours on two cores.
set -eu
# shellcheck source=common.sh
. "$(dirname "$0")/common.sh"
out=${CPOSE_RESULTS:-runs/results}/imu
room=configs/synthetic_imu.toml
euroc=configs/euroc_v102_imu.toml
euroc_windows=configs/euroc_v102_imu_windows.toml
euroc_data="euroc.path=\"$data/euroc/V1_02_excerpt\""
absolute='slam.methods=["none","loose","tight","accel","combined"]'
relative='slam.methods=["baseline","prev","prev_loose","prev_tight","prev_accel","prev_combined"]'
metrics=ate_rmse_cm,start_rpe_trans_rmse_cm,start_rpe_rot_rmse_deg,rpe_rot_rmse_deg,lost_frames,first_lost,recovered_frames

# windows NAME CONFIG [ARGS...]: NAME with the absolute PoseNet in windows of 2 s (3 bands) and
# the gyroscope's weight at a tenth; ARGS add the rotation rate (a fifth of the config's).
windows() {
    windows_name=$1
    windows_config=$2
    shift 2
    run "$windows_name" "$windows_config" --set imu.window_secs=2 --set imu.window_bands=3 \
        --set imu.gyro_weight=0.1 "$@"
}

table_synthetic() {
    run synthetic "$room"
    table "Synthetic room at 5 Hz, simulated IMU (configs/synthetic_imu.toml)" "$metrics" \
        "$out/synthetic"
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

# The relative family at 5 Hz on the flight, seeds 0 (euroc-5hz) to 3.
table_euroc_5hz() {
    run euroc-5hz "$euroc" --set "$euroc_data" --set data.stride=2 --set "$relative"
    dirs="$out/euroc-5hz"
    for seed in 1 2 3; do
        run "euroc-5hz-s$seed" "$euroc" --set "$euroc_data" --set data.stride=2 \
            --set "$relative" --set "run.seed=$seed"
        dirs="$dirs $out/euroc-5hz-s$seed"
    done
    # shellcheck disable=SC2086
    table "EuRoC V1_02 at 5 Hz, every second frame (configs/euroc_v102_imu.toml)" \
        "$metrics" $dirs
}

table_euroc() {
    run euroc "$euroc" --set "$euroc_data"
    table "EuRoC V1_02 at 10 Hz (configs/euroc_v102_imu.toml)" "$metrics" "$out/euroc"
}

table_windows_gyro() {
    dirs=
    for seed in 0 1 2 3; do
        run "euroc-windows-gyro-s$seed" "$euroc_windows" --set "$euroc_data" \
            --set "run.seed=$seed"
        dirs="$dirs $out/euroc-windows-gyro-s$seed"
    done
    for seed in 1 2 3; do
        run "euroc-baseline-s$seed" "$euroc" --set "$euroc_data" \
            --set 'slam.methods=["baseline"]' --set "run.seed=$seed"
        dirs="$dirs $out/euroc-baseline-s$seed"
    done
    for seed in 0 1; do
        windows "room-windows-gyro-s$seed" "$room" --set "$absolute" \
            --set imu.lr_rotation=1e-4 --set "run.seed=$seed"
        dirs="$dirs $out/room-windows-gyro-s$seed"
    done
    # shellcheck disable=SC2086
    table "Windows of 2 s, gyroscope weight 0.1 (configs/euroc_v102_imu_windows.toml; the room)" \
        "$metrics" $dirs
}

tables=$(tables_from "synthetic gyro_weight accel_tie euroc_5hz euroc windows_gyro" "$@")
# shellcheck disable=SC2086 # one word per table
run_tables $tables
