#!/bin/sh
# The tables of docs/results/trajectory.md: pose fields fitted to sparse poses, with and without
# the gyroscope, scored on the held-out poses: the built-in synthetic motion and 20 s of the real
# EuRoC V1_02 flight.
#
#   scripts/results/trajectory.sh [TABLE...]
#
# TABLE is synthetic or euroc (default: both). Runs go to runs/results/trajectory/NAME
# (common.sh: environment); a finished run is kept and an interrupted one resumed. The tables are
# printed to stdout.
set -eu
# shellcheck source=common.sh
. "$(dirname "$0")/common.sh"
out=${CPOSE_RESULTS:-runs/results}/trajectory
metrics=rot_err_deg,rot_rmse_deg,trans_err_m,ang_vel_rmse_rad_s

table_synthetic() {
    run synthetic configs/trajectory_fit.toml
    table "Built-in synthetic motion, every 20th pose (configs/trajectory_fit.toml)" \
        "$metrics" "$out/synthetic"
}

table_euroc() {
    run euroc configs/euroc_v102_fit.toml --set "data.path=\"$data/euroc/V1_02_excerpt\""
    table "EuRoC V1_02, every 20th pose, real gyroscope (configs/euroc_v102_fit.toml)" \
        "$metrics" "$out/euroc"
}

tables=$(tables_from "synthetic euroc" "$@")
for t in $tables; do
    "table_$t"
done
