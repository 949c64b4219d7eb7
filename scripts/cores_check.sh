#!/usr/bin/env bash
# Issue 38's measurement on a many-core machine (the device machine's CPU): wall and CPU seconds
# of the benchmark render (six_lights, 640x360, smis-exact) at 1, 2, 4, 8 and 16 threads, for
# 655,360 and 2,621,440 planes, and the speedup and CPU growth against 1 thread (logs:
# docs/measurements/*-cores_check.log; docs/results.md "On 16 cores").
#
#   scripts/cores_check.sh [BINARY] [THREADS...]     (default: target/release/fogplanes, 1 2 4 8 16)
#
# Then the same one-thread render alone and one per core at once, as separate processes: what
# the machine itself costs a process beside others (about 10 s more on 16 cores, an estimate).
#
# Builds nothing: run `cargo build --release` first. About 2.5 minutes on 16 cores (the table
# took 146 s on the H100's machine, 2026-11-28). Times with
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

# The machine's share of the CPU growth above, apart from fogplanes' threads: the same
# one-thread render alone, then one per core at once, each its own process (no pool, no schedule,
# nothing shared but the machine). Where a process beside the others takes more CPU seconds than
# alone, the cores' shared clock, caches and memory cost that much to any program; what the
# threads' rows above grow beyond it is fogplanes' own. CONCURRENT=0 leaves it out.
if [ "${CONCURRENT:-1}" != 0 ]; then
    n=$(nproc)
    echo
    echo "the same render (163840 planes, --threads 1) alone, then $n processes at once:"
    echo "| processes | CPU s a process: median | min | max | median against alone |"
    echo "|---:|---:|---:|---:|---:|"
    TIMEFORMAT='%U %S'
    one() {
        { time "$bin" render media_scenes/six_lights.toml --quiet --resolution 640x360 -e smis-exact \
            --planes 163840 --threads 1 -o "$out/c$1.exr" >/dev/null 2>&1; } 2>"$out/c$1.time"
    }
    alone=
    for k in 1 "$n"; do
        pids=()
        for i in $(seq 1 "$k"); do one "$i" & pids+=($!); done
        # Each waited for by its pid, so that a render that fails stops the script (set -e).
        for pid in "${pids[@]}"; do wait "$pid"; done
        cat "$out"/c*.time | awk '{ print $1 + $2 }' | sort -g >"$out/cpu"
        rm -f "$out"/c*.time
        median=$(awk '{ a[NR] = $1 } END { print (NR % 2) ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2 }' "$out/cpu")
        [ -z "$alone" ] && alone=$median
        awk -v k="$k" -v m="$median" -v a="$alone" 'NR == 1 { lo = $1 } { hi = $1 }
            END { printf "| %s | %.2f | %.2f | %.2f | %.2f |\n", k, m, lo, hi, m / a }' "$out/cpu"
    done
fi
