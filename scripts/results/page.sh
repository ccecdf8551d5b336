#!/bin/sh
# Regenerates the tables of a results page: runs scripts/results/SETTING.sh (which runs or resumes
# what is missing and prints its tables) and writes its output into docs/results/SETTING.md
# between the lines `<!-- tables:begin -->` and `<!-- tables:end -->`, replacing what was there.
#
#   scripts/results/page.sh SETTING [TABLE...]
#
# SETTING is planar, trajectory, nerf, events, slam or imu; TABLEs are passed on to its script
# (default: all its tables, which then replace everything between the markers). With TABLEs, only
# those tables are replaced (each table starts at its line `<!-- table:NAME -->`); the page's other
# tables stay, and a table new to the page is added at the end. The environment of common.sh
# applies.
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
# Blocks start at `<!-- table:NAME -->`; with TABLEs the page's blocks of other names are kept.
partial=$([ $# -gt 0 ] && echo 1 || echo 0)
awk -v tables="$tables" -v begin="$begin" -v end="$end" -v partial="$partial" '
    # block(line, kind): files line into the current block of kind "old" or "new".
    function block(line, kind,    name) {
        if (line ~ /^<!-- table:[^ ]+ -->$/) {
            name = line
            sub(/^<!-- table:/, "", name)
            sub(/ -->$/, "", name)
            current[kind] = name
            order[kind, ++count[kind]] = name
        }
        if (current[kind] != "") text[kind, current[kind]] = text[kind, current[kind]] line "\n"
    }
    BEGIN {
        while ((getline line < tables) > 0) block(line, "new")
    }
    $0 == begin {
        print
        inside = 1
        next
    }
    # emit(t): a block with one blank line after it.
    function emit(t) {
        sub(/\n+$/, "\n", t)
        printf "%s\n", t
    }
    $0 == end {
        if (partial) {
            print ""
            for (i = 1; i <= count["old"]; i++) {
                name = order["old", i]
                emit((("new", name) in text) ? text["new", name] : text["old", name])
            }
            for (i = 1; i <= count["new"]; i++) {
                name = order["new", i]
                if (!(("old", name) in text)) emit(text["new", name])
            }
        } else {
            close(tables)
            while ((getline line < tables) > 0) print line
            print ""
        }
        print
        inside = 0
        next
    }
    inside {
        block($0, "old")
        next
    }
    { print }
' "$page" >"$page.tmp"
mv "$page.tmp" "$page"
echo "$page: tables written" >&2
