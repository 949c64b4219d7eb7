#!/usr/bin/env bash
# The GPU check of issue 37, in one command on a machine with a GPU (a few minutes on an H100):
# per estimator, the GPU gather's G hits/s (its timestamps) and the render's end-to-end time at
# 640x360 with 40,960 and 655,360 planes (the benchmark scene, whole pixels), the agreement with
# the CPU's image (relative MSE, `fogplanes compare`), the same for fog that scatters forward
# (media_scenes/forward_fog.toml at the first count), the GPU time by the work items' size and
# with the driver's transcendental functions and without wgpu's shader runtime checks, then
# the CPU renderer's wall time on 1, 2, 4, 8 and all threads, and the machine's threads per core;
# then the timeline of smis-exact's renders and cmis-exact's first (`FOGPLANES_TRACE=1`: each
# step's start, end and thread, then each GPU pass's time by its own timestamps,
# crates/core/src/trace.rs) into a log of its own, gpu_timeline.log.
#
#   scripts/gpu_check.sh --fetch   # here, once, with a network: the Vulkan loader and libglvnd
#                                  # as Debian packages into .gl/ (the device machine has none)
#   scripts/gpu_check.sh           # there, with target/release/fogplanes and .gl/ carried
#
# Vulkan there: if the system has no loader, the packages of .gl/ are unpacked over / and
# ldconfig run (without libglvnd0 the NVIDIA ICD does not load: "no Vulkan adapter"), and the
# NVIDIA ICD file is named when the loader would not find it. Output goes to stdout and, where
# $OUT is set, to $OUT/gpu_check.log.
set -u
cd "$(dirname "$0")/.."
if [ "${1:-}" = "--fetch" ]; then
    grep -qx '/.gl/' .git/info/exclude 2>/dev/null || echo /.gl/ >>.git/info/exclude
    mkdir -p .gl /tmp/amd64/partial
    o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
    # shellcheck disable=SC2086
    apt-get $o update -qq && (cd .gl && apt-get $o download libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
    ls .gl
    exit
fi
B=${FOGPLANES:-target/release/fogplanes}
S=media_scenes/six_lights.toml
# A dry run elsewhere (lavapipe) takes smaller ones: GPU_CHECK_RESOLUTION=64x36 GPU_CHECK_PLANES=2048.
R=${GPU_CHECK_RESOLUTION:-640x360}
P=${GPU_CHECK_PLANES:-40960 655360}
first=${P%% *} last=${P##* }
work=$(mktemp -d)
log=${OUT:+$OUT/gpu_check.log}
log=${log:-/dev/null}
# One render: its summary line (gather, GPU time and G hits/s, total: from the scene loaded to
# the image finished in memory, without process start and file writing).
render() { timeout 150 "$B" render "$S" --resolution "$R" -q "$@" 2>&1 | grep -v XDG_RUNTIME_DIR | grep -v '^wrote'; }
{
date -u
nvidia-smi -L 2>/dev/null
if ! ldconfig -p 2>/dev/null | grep -q 'libvulkan.so.1 '; then
    if ls .gl/*.deb >/dev/null 2>&1; then
        for f in .gl/*.deb; do dpkg -x "$f" /; done
        ldconfig
        echo "Vulkan loader and libglvnd unpacked from .gl/"
    else
        echo "no Vulkan loader, and no .gl/ to unpack (scripts/gpu_check.sh --fetch first)"
    fi
fi
nv=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
if [ -z "${VK_DRIVER_FILES:-}" ] && [ -f "$nv" ]; then
    export VK_DRIVER_FILES=$nv __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
    echo "VK_DRIVER_FILES=$nv"
fi
echo "threads per core: $(lscpu 2>/dev/null | awk -F: '/Thread\(s\) per core/ {gsub(/ /, "", $2); print $2}'), logical CPUs: $(nproc)"
for planes in $P; do
    for e in unweighted cmis-cosine smis-cosine smis-exact "smis-exact --orientations 8" cmis-exact; do
        name=${e// /_}
        # Twice: the first process compiles the estimator's shaders (its total includes them; the
        # driver keeps them in its disk cache), the second finds them compiled.
        # shellcheck disable=SC2086
        render --planes $planes -e $e --device gpu -o "$work/gpu_$name.exr" | sed "s/^/gpu $planes first: /"
        # shellcheck disable=SC2086
        render --planes $planes -e $e --device gpu -o "$work/gpu_$name.exr" | sed "s/^/gpu $planes again: /"
        # shellcheck disable=SC2086
        render --planes $planes -e $e -o "$work/cpu_$name.exr" | sed "s/^/cpu $planes: /"
        printf 'agreement %s %s: ' "$planes" "$e"
        timeout 60 "$B" compare "$work/gpu_$name.exr" "$work/cpu_$name.exr" | tr '\n' ' ' | tr -s ' '
        echo
        # The ray sets made on the CPU and uploaded (`--rays-on-cpu`: the CPU's rays bit for bit,
        # 18 uploads and submissions; the default makes them on the GPU, docs/gpu.md), for
        # smis-exact: its end to end and its agreement with the CPU.
        if [ "$e" = smis-exact ]; then
            # shellcheck disable=SC2086
            render --planes $planes -e $e --device gpu --rays-on-cpu -o "$work/cpurays_$name.exr" | sed "s/^/gpu cpu-rays $planes: /"
            printf 'agreement cpu-rays %s %s: ' "$planes" "$e"
            timeout 60 "$B" compare "$work/cpurays_$name.exr" "$work/cpu_$name.exr" | tr '\n' ' ' | tr -s ' '
            echo
        fi
    done
done
# Fog that scatters forward (media_scenes/forward_fog.toml, g = 0.85, the planes' lobes of
# docs/mathematics.md section 2.5, their weight in each plane's phase_scale): the GPU against
# the CPU, smis-exact and cmis-exact, at the first planes count (a second process each).
for e in smis-exact cmis-exact; do
    for d in gpu gpu cpu; do
        timeout 150 "$B" render media_scenes/forward_fog.toml --resolution "$R" -q --planes "$first" -e "$e" \
            --device "$d" -o "$work/ff_$d.exr" 2>&1 | grep -v XDG_RUNTIME_DIR | grep -v '^wrote' | sed "s/^/forward fog $d $first: /"
    done
    printf 'agreement forward fog %s %s: ' "$first" "$e"
    timeout 60 "$B" compare "$work/ff_gpu.exr" "$work/ff_cpu.exr" | tr '\n' ' ' | tr -s ' '
    echo
done
# The work items' size (docs/gpu.md: a batch's items aim at several waves; the first planes
# count's size is the default's own), smis-exact and cmis-exact with the first planes count, a
# second process each: the GPU time by the item's planes decides the default.
for item in 16 32 64 128 256 512; do
    for e in smis-exact cmis-exact; do
        FOGPLANES_GPU_ITEM_PLANES=$item render --planes "$first" -e $e --device gpu -o "$work/item.exr" | sed "s/^/gpu item $item $first: /"
    done
done
# What else only a device can decide (issue 45; gpu/mod.rs `Tuning`): the driver's exp, log
# and atan instead of the CPU's polynomials (FOGPLANES_GPU_MATH=native), wgpu's shader runtime
# checks off (FOGPLANES_GPU_CHECKS=off), and both, against the defaults, for smis-exact and
# cmis-exact at each planes count: two rounds, the settings alternated within each (the first
# round's process compiles each setting's shaders; read the second's GPU time), then how far
# the driver's functions move the image from the polynomials' (relative MSE). Left out with
# GPU_CHECK_TUNED=no (a base build that knows no such variables).
[ "${GPU_CHECK_TUNED:-yes}" = no ] && P_TUNED= || P_TUNED=$P
for planes in $P_TUNED; do
    for e in smis-exact cmis-exact; do
        for round in 1 2; do
            for tuned in FOGPLANES_GPU_MATH=polynomials FOGPLANES_GPU_MATH=native FOGPLANES_GPU_CHECKS=off "FOGPLANES_GPU_MATH=native FOGPLANES_GPU_CHECKS=off"; do
                name=${tuned// /+}
                # shellcheck disable=SC2086
                env $tuned timeout 150 "$B" render "$S" --resolution "$R" -q --planes "$planes" -e $e --device gpu -o "$work/tuned_$name.exr" 2>&1 |
                    grep -v XDG_RUNTIME_DIR | grep -v '^wrote' | sed "s/^/gpu tuned $name round $round $planes: /"
            done
        done
        printf 'agreement tuned native against polynomials %s %s: ' "$planes" "$e"
        timeout 60 "$B" compare "$work/tuned_FOGPLANES_GPU_MATH=native.exr" "$work/tuned_FOGPLANES_GPU_MATH=polynomials.exr" | tr '\n' ' ' | tr -s ' '
        echo
    done
done
# A setting against the default, smis-exact at the first planes count: two rounds, the two
# values alternated within each (the first round's processes compile the shaders; read the
# second's lines), then whether the images are the same bits, or how far apart (relative MSE).
#   ab NAME VARIABLE DEFAULT OTHER [render arguments]
ab() {
    local name=$1 var=$2 one=$3 other=$4
    shift 4
    for round in 1 2; do
        for how in "$one" "$other"; do
            env "$var=$how" timeout 150 "$B" render "$S" --resolution "$R" -q --planes "$first" -e smis-exact \
                --device gpu -o "$work/${name}_$how.exr" "$@" 2>&1 |
                grep -v XDG_RUNTIME_DIR | grep -v '^wrote' | sed "s/^/gpu $name $how round $round $first: /"
        done
    done
    printf 'agreement %s %s against %s %s: ' "$name" "$other" "$one" "$first"
    timeout 60 "$B" compare "$work/${name}_$other.exr" "$work/${name}_$one.exr" | tr '\n' ' ' | tr -s ' '
    echo
}
if [ -n "$P_TUNED" ]; then
    # K orientations made at each hit (the default) or once a gathering into a table
    # (FOGPLANES_GPU_ORIENTATIONS=table), with K = 8.
    ab orientations FOGPLANES_GPU_ORIENTATIONS per-hit table --orientations 8
    # K read from the gather's parameters (the default) or a constant of its pipeline, which a
    # driver can unroll the loop over (FOGPLANES_GPU_K=constant), with K = 8: the same bits.
    ab k FOGPLANES_GPU_K uniform constant --orientations 8
    # A chunk's pieces joined into one gathering, their work items in one dispatch a round (the
    # default), or gathered apart, a piece's own dispatches each (FOGPLANES_GPU_PIECES=apart):
    # the benchmark's 18 pieces (at 655,360 planes a piece is about a chunk); the end to end
    # and the gather dispatches in the lines too. A joined round's work items are sized by all
    # its pairs: within f32 rounding, the same bits where the size is fixed.
    ab pieces FOGPLANES_GPU_PIECES joined apart
    # The binning in two tiers, each tile's candidates from its block of 4 x 4 tiles (the
    # default), or in one, every plane of a batch tested at every tile (FOGPLANES_GPU_BINNING=flat):
    # the same lists, the same bits; the lines split the GPU time into the reach and the
    # binning, and the gather.
    ab binning FOGPLANES_GPU_BINNING blocks flat
    # A tile's pixels taken by a warp of 32 in blocks of 8 x 4 (the default), or two rows of 16
    # (FOGPLANES_GPU_LANES=rows), as before: the same bits; the lines split the GPU time.
    ab lanes FOGPLANES_GPU_LANES blocks rows
fi
# The CPU renderer on 1, 2, 4, 8 and all threads (smis-exact, 40,960 planes).
for t in 1 2 4 8 all; do
    threads=()
    [ "$t" = all ] || threads=(--threads "$t")
    # bash's `time` (the device machine's image may have no GNU time).
    TIMEFORMAT="cpu threads $t: wall %R s, user %U s, sys %S s"
    { time "$B" render "$S" --resolution "$R" --planes 40960 -q "${threads[@]}" -o "$work/t.exr" 2>&1 | grep -v '^wrote' | sed "s/^/  /"; } 2>&1
done
# The timeline: where each end to end goes, step by step, and the GPU's time pass by pass (a
# second process each: smis-exact at the first planes count and the last, cmis-exact at the
# first), into a log of its own (here, in the Vulkan set-up above).
{
date -u
for run in "smis-exact $first" "smis-exact $last" "cmis-exact $first"; do
    e=${run% *} planes=${run#* }
    echo "== $e, $planes planes, --device gpu, FOGPLANES_TRACE=1"
    FOGPLANES_TRACE=1 render --planes "$planes" -e "$e" --device gpu -o "$work/trace.exr"
done
} >"${OUT:-$work}/gpu_timeline.log" 2>&1
date -u
} 2>&1 | tee "$log"
rm -rf "$work"
