#!/bin/sh
# Issue 38's measurement on a many-core machine (the device machine's CPU): wall and CPU seconds
# of the benchmark render (six_lights, 640x360, smis-exact) at 1, 2, 4, 8 and 16 threads, for
# 655,360 and 2,621,440 planes, and the speedup and CPU growth against 1 thread. Not run yet:
# no session has had such a machine (docs/scaling/threads.md).
#
#   scripts/cores_check.sh [BINARY] [THREADS...]     (default: target/release/fogplanes, 1 2 4 8 16)
#
# Builds nothing: run `cargo build --release` first. About 4 minutes on 16 cores.
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
        # GNU time's %e wall, %U + %S CPU of the whole command.
        /usr/bin/time -f "%e %U %S" -o "$out/time" "$bin" render media_scenes/six_lights.toml --quiet \
            --resolution 640x360 -e smis-exact --planes "$planes" --threads "$t" -o "$out/x.exr"
        read -r wall user sys < "$out/time"
        cpu=$(echo "$user + $sys" | bc -l)
        [ -z "$wall1" ] && { wall1=$wall; cpu1=$cpu; }
        printf '| %s | %s | %.2f | %.2f | %.2fx | %.2f |\n' "$planes" "$t" "$wall" "$cpu" \
            "$(echo "$wall1 / $wall" | bc -l)" "$(echo "$cpu / $cpu1" | bc -l)"
    done
done
