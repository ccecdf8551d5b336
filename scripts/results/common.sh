# Sourced by the scripts in scripts/results/ (not run on its own): how a results script runs cpose
# and prints a table.
#
# Environment:
#   CPOSE          the cpose binary (default: target/release/cpose, built first)
#   CPOSE_RESULTS  the folder of all results runs (default: runs/results)
#   CPOSE_DATA_DIR the shared data folder (default: ../shared/data, beside the checkout)
#   CPOSE_SCALE    if set, --set run.iterations_scale=CPOSE_SCALE for new runs (a quick check;
#                  its numbers are not the published ones)
#   CPOSE_THREADS  if set, --set run.threads=CPOSE_THREADS for new runs
#
# Progress and cpose's log go to stderr; stdout carries only the tables, so
# `scripts/results/page.sh SETTING` can write them into docs/results/SETTING.md.

# shellcheck shell=sh disable=SC2154
# (SC2154: $out, the run folder of the setting, is set by the calling script.)

# The configs' relative data paths hold from the repository root.
cd "$(dirname "$0")/../.." || exit 2

# shellcheck disable=SC2034 # used by the calling scripts
data=${CPOSE_DATA_DIR:-../shared/data}
cpose=

# need_cpose: sets $cpose, building target/release/cpose once unless CPOSE names a binary.
need_cpose() {
    if [ -n "$cpose" ]; then
        return 0
    elif [ -n "${CPOSE:-}" ]; then
        cpose=$CPOSE
    else
        cargo build --release -p cpose-cli >&2
        cpose=target/release/cpose
    fi
}

# finished DIR: whether DIR holds a study whose every unit finished.
finished() {
    [ -f "$1/study.json" ] && grep -q '"finished": true' "$1/study.json"
}

# claim DIR: whether this script may make DIR. A script claims a run by creating DIR.claim
# holding its process id; a claim whose process has ended is taken over. So two copies of one
# script (`scripts/results/nerf.sh grid` twice) share its runs, each making the runs the other
# has not claimed.
claim() {
    mkdir -p "$(dirname "$1")"
    if ! mkdir "$1.claim" 2>/dev/null; then
        claim_pid=$(cat "$1.claim/pid" 2>/dev/null || true)
        if [ -n "$claim_pid" ] && kill -0 "$claim_pid" 2>/dev/null; then
            return 1
        fi
        echo "$1: claimed by process ${claim_pid:-?}, which has ended; taken over" >&2
    fi
    echo $$ >"$1.claim/pid"
}

# unclaim DIR: gives up the claim on DIR.
unclaim() {
    rm -rf "$1.claim"
}

# run NAME CONFIG [ARGS...]: the run folder $out/NAME made by `cpose run CONFIG ARGS...`. A
# finished run is kept, an interrupted one resumed (`cpose run --resume`), any other started anew,
# and one claimed by another script (claim) is left to it.
run() {
    need_cpose
    run_dir=$out/$1
    run_config=$2
    shift 2
    if finished "$run_dir"; then
        echo "$run_dir: finished, kept" >&2
        return 0
    elif ! claim "$run_dir"; then
        echo "$run_dir: being made by process $claim_pid, left to it" >&2
        return 0
    elif [ -f "$run_dir/config.toml" ]; then
        echo "$run_dir: resuming" >&2
        "$cpose" run --resume "$run_dir" >&2
    else
        if [ -n "${CPOSE_SCALE:-}" ]; then
            set -- "$@" --set "run.iterations_scale=$CPOSE_SCALE"
        fi
        if [ -n "${CPOSE_THREADS:-}" ]; then
            set -- "$@" --set "run.threads=$CPOSE_THREADS"
        fi
        echo "$run_dir: cpose run $run_config $*" >&2
        "$cpose" run "$run_config" --out "$run_dir" --force "$@" >&2
    fi
    unclaim "$run_dir"
}

# await RUN...: waits until every run folder is finished, while another script makes those it
# has claimed; fails on a run that is neither finished nor claimed.
await() {
    for d in "$@"; do
        while ! finished "$d"; do
            await_pid=$(cat "$d.claim/pid" 2>/dev/null || true)
            if [ -z "$await_pid" ] || ! kill -0 "$await_pid" 2>/dev/null; then
                echo "$d: not finished and not being made; run the script again" >&2
                return 1
            fi
            sleep 30
        done
    done
}

# made_by RUN...: the commit checked out (and whether it has changes), the commits the runs were
# made by (from their provenance.json) and the machine.
made_by() {
    head_commit=$(git rev-parse --short HEAD 2>/dev/null || echo unknown)
    if [ -n "$(git status --porcelain 2>/dev/null)" ]; then
        head_commit="$head_commit, dirty"
    fi
    # A run made by a build with uncommitted changes is marked "+dirty".
    run_commits=$(for d in "$@"; do
        commit=$(sed -n 's/^  "commit": "\([0-9a-f]\{7\}\).*/\1/p' "$d/provenance.json" 2>/dev/null)
        if grep -q '^  "dirty": true' "$d/provenance.json" 2>/dev/null; then
            commit="$commit+dirty"
        fi
        echo "$commit"
    done | sort -u | tr '\n' ' ' | sed 's/ $//')
    cpu=$(sed -n 's/^model name[[:space:]]*:[[:space:]]*//p' /proc/cpuinfo 2>/dev/null | head -n 1)
    cpus=$(nproc 2>/dev/null || getconf _NPROCESSORS_ONLN 2>/dev/null || echo "?")
    printf 'commit %s (runs by %s), %s, %s CPUs' \
        "$head_commit" "${run_commits:-unknown}" "${cpu:-unknown CPU}" "$cpus"
}

# table TITLE METRICS RUN...: a heading, a line with the command, commit and machine, and the
# metrics of the run folders as one Markdown table (one row per condition and method; the rows of
# single seeds are left out).
table() {
    table_title=$1
    table_metrics=$2
    shift 2
    if [ "${tables_pass:-print}" = runs ]; then
        return 0
    fi
    need_cpose
    await "$@"
    table_text=$("$cpose" table "$@" --metrics "$table_metrics")
    # The command, run from the runs' common folder when they share one.
    table_parent=$(dirname "$1")
    table_runs=
    for d in "$@"; do
        if [ "$(dirname "$d")" != "$table_parent" ]; then
            table_parent=
            table_runs=$*
            break
        fi
        table_runs="$table_runs${table_runs:+ }$(basename "$d")"
    done
    printf '\n### %s\n\n' "$table_title"
    # shellcheck disable=SC2016 # the backquotes are Markdown
    printf '`cpose table %s --metrics %s`%s: %s.\n\n' "$table_runs" "$table_metrics" \
        "${table_parent:+ in \`$table_parent\`}" "$(made_by "$@")"
    printf '%s\n' "$table_text" | grep -v '/runs/[0-9]* |'
}

# tables_from "ALL" [TABLE...]: the tables asked for, checked against ALL (all of them when none
# is asked for), as one line.
tables_from() {
    tables_all=$1
    shift
    # shellcheck disable=SC2086 # one word per table
    [ $# -gt 0 ] || set -- $tables_all
    for t in "$@"; do
        case " $tables_all " in
        *" $t "*) ;;
        *)
            echo "$0: unknown table '$t' (tables: $tables_all)" >&2
            exit 2
            ;;
        esac
    done
    echo "$*"
}

# run_tables TABLE...: each table's runs and table (the function table_TABLE of the calling
# script), headed by a line `<!-- table:TABLE -->` by which page.sh replaces one table of a page
# and keeps the others. Every table's runs are made first and the tables printed after, so a
# second copy of the script goes on to the next table's runs instead of waiting for a table.
run_tables() {
    tables_pass=runs
    for t in "$@"; do
        "table_$t"
    done
    tables_pass=print
    for t in "$@"; do
        printf '\n<!-- table:%s -->\n' "$t"
        "table_$t"
    done
}
