#!/bin/sh
# Moved: the paper's pose-noise grid is the table `grid` of scripts/results/nerf.sh (runs in
# runs/results/nerf/grid, the table on docs/results/nerf.md). This name is kept for the
# configs and notes that still point here.
set -eu
if [ $# -gt 0 ]; then
    echo "$0: moved to scripts/results/nerf.sh grid, which takes no OUT_DIR or --set" \
        "(CPOSE_RESULTS, CPOSE_SCALE and CPOSE_THREADS: see scripts/results/common.sh)" >&2
    exit 2
fi
exec "$(dirname "$0")/results/nerf.sh" grid
