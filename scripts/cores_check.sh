#!/usr/bin/env bash
# Issue 38's measurement on a many-core machine (the device machine's CPU): wall and CPU seconds
# of the benchmark render (six_lights, 640x360, smis-exact) at 1, 2, 4, 8 and 16 threads, for
# 655,360 and 2,621,440 planes, and the speedup and CPU growth against 1 thread. Not run yet:
# no session has had such a machine (docs/scaling/threads.md).
#
#   scripts/cores_check.sh [BINARY] [THREADS...]     (default: target/release/fogplanes, 1 2 4 8 16)
#
# Builds nothing: run `cargo build --release` first. About 4 minutes on 16 cores. Times with
# bash's own `time` and reckons with awk: the device machine's image may have neither GNU time
# nor bc.
set -eu
bin=${1:-target/release/fogplanes}
[ $# -gt 0 ] && shift
threads=${*:-1 2 4 8 16}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
echo "cores: $(nproc), $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2)"
echo "| planes | threads | wall s | CPU s | speedup | CPU / 1 thread |"
echo "|---:|---:|---:|---:|---:|---:|"
for planes in 655360 2621440; do
    wall1=; cpu1=
    for t in $threads; do
        # bash's `time`: wall, then user and sys of the command's process.
        TIMEFORMAT='%R %U %S'
        { time "$bin" render media_scenes/six_lights.toml --quiet --resolution 640x360 \
            -e smis-exact --planes "$planes" --threads "$t" -o "$out/x.exr" >/dev/null 2>&1; } 2>"$out/time"
        read -r wall user sys < "$out/time"
        cpu=$(awk "BEGIN { print $user + $sys }")
        [ -z "$wall1" ] && { wall1=$wall; cpu1=$cpu; }
        awk -v p="$planes" -v t="$t" -v w="$wall" -v c="$cpu" -v w1="$wall1" -v c1="$cpu1" \
            'BEGIN { printf "| %s | %s | %.2f | %.2f | %.2fx | %.2f |\n", p, t, w, c, w1 / w, c / c1 }'
    done
done
