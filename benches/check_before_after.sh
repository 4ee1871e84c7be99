#!/usr/bin/env bash
# Whole-process `nanomotion check` times of two builds, side by side in one run
# (before, after, before, after, ... per graph, so that both see the same load):
# the generated loops and chains of benches/stability_gate.rs and
# benches/graph_build.rs (written to target/bench-graphs/ by
# `cargo bench --bench stability_gate -- --list` and
# `cargo bench --bench graph_build -- --list`).
#
#   benches/check_before_after.sh BEFORE_BINARY AFTER_BINARY GRAPH.yaml...
#
# Prints per graph: seconds before, seconds after, their ratio, and the
# before build's verdict when it fails (exit status and last line).
set -u
before=$1
after=$2
shift 2
printf '%-28s %10s %10s %8s\n' graph before_s after_s ratio
for g in "$@"; do
    t0=$(date +%s.%N)
    "$before" check "$g" > /tmp/check_before.out 2>&1
    sb=$?
    t1=$(date +%s.%N)
    "$after" check "$g" > /tmp/check_after.out 2>&1
    sa=$?
    t2=$(date +%s.%N)
    b=$(echo "$t1 - $t0" | bc)
    a=$(echo "$t2 - $t1" | bc)
    printf '%-28s %10.3f %10.3f %8.1f' "$(basename "$g")" "$b" "$a" "$(echo "$b / $a" | bc -l)"
    if [ "$sb" -ne 0 ]; then
        printf '  (before: exit %s: %s)' "$sb" "$(tail -c 160 /tmp/check_before.out | tr '\n' ' ')"
    fi
    if [ "$sa" -ne 0 ]; then
        printf '  (after: exit %s)' "$sa"
    fi
    printf '\n'
done
