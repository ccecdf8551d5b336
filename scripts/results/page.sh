#!/bin/sh
# Regenerates the tables of a results page: runs scripts/results/SETTING.sh (which runs or resumes
# what is missing and prints its tables) and writes its output into docs/results/SETTING.md
# between the lines `<!-- tables:begin -->` and `<!-- tables:end -->`, replacing what was there.
#
#   scripts/results/page.sh SETTING [TABLE...]
#
# SETTING is planar, trajectory, nerf, events, slam or imu; TABLEs are passed on to its script
# (default: all its tables; the page then holds only the tables asked for). The environment of
# common.sh applies.
set -eu
if [ $# -lt 1 ]; then
    echo "usage: $0 SETTING [TABLE...]" >&2
    exit 2
fi
setting=$1
shift
here=$(cd "$(dirname "$0")" && pwd)
script=$here/$setting.sh
page=$here/../../docs/results/$setting.md
if [ ! -x "$script" ] || [ ! -f "$page" ]; then
    echo "$0: no results script $script or page $page" >&2
    exit 2
fi
begin='<!-- tables:begin -->'
end='<!-- tables:end -->'
if ! grep -qxF "$begin" "$page" || ! grep -qxF "$end" "$page"; then
    echo "$0: $page has no lines $begin and $end" >&2
    exit 2
fi

tables=$(mktemp)
trap 'rm -f "$tables" "$page.tmp"' EXIT
"$script" "$@" >"$tables"
awk -v tables="$tables" -v begin="$begin" -v end="$end" '
    $0 == begin {
        print
        while ((getline line < tables) > 0) print line
        print ""
        skip = 1
        next
    }
    $0 == end { skip = 0 }
    !skip { print }
' "$page" >"$page.tmp"
mv "$page.tmp" "$page"
echo "$page: tables written" >&2
