#!/usr/bin/env bash
# A device session's one prepared call (issue 45: measure first): scripts/gpu_check.sh with this
# build, then with a base build where one is carried, scripts/cores_check.sh, and the GPU tests
# on the device's driver where their binary is carried; every log under $OUT.
#
# Here, before the call:
#   cargo build --release && cargo test --release --no-run
#   strip -o .gl/all target/release/deps/all-<hash>        # the test binary (`--no-run` names it)
#   cargo build --release -p fogplanes-bench --example prepare_planes && \
#       strip -o .gl/prepare_planes target/release/examples/prepare_planes   # 2 MB
#   git worktree add /tmp/base <commit> && (cd /tmp/base && CARGO_TARGET_DIR=/tmp/base-target \
#       cargo build --release) && strip -o .gl/base/fogplanes /tmp/base-target/release/fogplanes
# The call (device tool): `bash scripts/device_check.sh`, carrying target/release/fogplanes and
# .gl (the Vulkan loader's packages, `scripts/gpu_check.sh --fetch`), 64 MiB in all (stripped,
# each binary is about 12 MB). About 5 minutes on an H100 or H200: give it a timeout of 480 s.
# Dry run on lavapipe (2026-11-28, cores_check left out): `OUT=/tmp/dc GPU_CHECK_RESOLUTION=64x36
# GPU_CHECK_PLANES="2048 4096" scripts/device_check.sh`, every log whole, 81 s; again on
# 2026-12-03 (at 3c2c880, without .gl/: no base build, test binary or prepare_planes), gpu_check
# whole (rc 0) and cores_check cut at its 240 s on 2 cores (rc 124), 284 s.
# The base build's gpu_check leaves out the settings only this build knows (GPU_CHECK_TUNED=no);
# the reply ends with this build's GPU time by setting (`gpu tuned`, gpu/mod.rs `Tuning`).
# Its logs: gpu_check.log and gpu_timeline.log (this build), base/gpu_check.log and
# base/gpu_timeline.log, cores_check.log, gpu_tests.log, devices.log, prepare_planes.log (the
# CPU's cost of preparing a plane, step by step, on the device machine's cores). Commit them under
# docs/measurements/ with the date, the device, the commits and this command.
cd "$(dirname "$0")/.."
B=target/release/fogplanes
out=${OUT:?set OUT to the folder for the logs}
for f in .gl/*.deb; do dpkg -x "$f" /; done
ldconfig
nv=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
if [ -z "${VK_DRIVER_FILES:-}" ] && [ -f "$nv" ]; then
    export VK_DRIVER_FILES=$nv __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
fi
{ date -u; nvidia-smi -L 2>/dev/null; "$B" devices; } >"$out/devices.log" 2>&1
timeout 170 bash scripts/gpu_check.sh >/dev/null 2>&1
echo "gpu_check rc $?" >>"$out/gpu_check.log"
if [ -x .gl/base/fogplanes ]; then
    mkdir -p "$out/base"
    OUT="$out/base" FOGPLANES=.gl/base/fogplanes GPU_CHECK_TUNED=no timeout 170 bash scripts/gpu_check.sh >/dev/null 2>&1
    echo "gpu_check (base) rc $?" >>"$out/base/gpu_check.log"
fi
if [ -x .gl/prepare_planes ]; then
    # The CPU's side of a GPU render (benches/examples/prepare_planes.rs): each step on one
    # thread, twice, and the render's own preparation whole on every core, in the benchmark's
    # pieces (2,560 planes) and in those of 655,360 planes (40,960), twice each.
    { for run in 1 2; do RAYON_NUM_THREADS=1 timeout 30 .gl/prepare_planes media_scenes/six_lights.toml 163840; done
      for piece in 2560 40960 2560 40960; do echo "pieces of $piece:"; timeout 30 .gl/prepare_planes media_scenes/six_lights.toml 655360 $piece | tail -3; done
    } >"$out/prepare_planes.log" 2>&1
fi
timeout 240 bash scripts/cores_check.sh "$B" >"$out/cores_check.log" 2>&1
echo "cores_check rc $?" >>"$out/cores_check.log"
if [ -x .gl/all ]; then
    # The test binary finds the repo at the path it was built in.
    [ -e /work/main ] || { mkdir -p /work && ln -s "$PWD" /work/main; }
    { date -u; FOGPLANES_REQUIRE_GPU=1 timeout 100 .gl/all --test-threads 4 gpu:: devices::; echo "gpu tests rc $?"; } \
        >"$out/gpu_tests.log" 2>&1
fi
# What the reply shows: each build's smis-exact lines on the GPU (second processes).
grep -h "^gpu [0-9]* again: smis-exact:" "$out/gpu_check.log" "$out"/base/gpu_check.log 2>/dev/null |
    sed 's/gather .*; GPU time/GPU time/' | cut -c1-300
# And this build's GPU time by setting (gpu/mod.rs `Tuning`), the second round's.
grep -h "^gpu tuned .* round 2 \|^gpu orientations .* round 2 \|^gpu k .* round 2 " "$out/gpu_check.log" 2>/dev/null | sed 's/: \([a-z0-9-]*\): [0-9]* planes.*GPU time \([0-9.]* s\).*/ \1: \2/' | sed 's/^gpu tuned //'
grep -h "^gpu pieces .* round 2 " "$out/gpu_check.log" 2>/dev/null | sed 's/: \([a-z0-9-]*\): [0-9]* planes.*GPU time \([0-9.]* s\).* \([0-9]* gather dispatches\).*total \([0-9.]* s\).*/ \1: GPU \2, \3, total \4/'
grep -h "^agreement pieces" "$out/gpu_check.log" 2>/dev/null
grep -h "^gpu binning .* round 2 \|^gpu lanes .* round 2 " "$out/gpu_check.log" 2>/dev/null | sed 's/: \([a-z0-9-]*\): [0-9]* planes.*GPU time \([0-9.]* s\) (the reach and the binning \([0-9.]* s\).*total \([0-9.]* s\).*/ \1: GPU \2, binning \3, total \4/'
grep -h "^agreement binning\|^agreement lanes" "$out/gpu_check.log" 2>/dev/null
grep -h "^agreement orientations\|^agreement k " "$out/gpu_check.log" 2>/dev/null
# The GPU's time pass by pass (FOGPLANES_TRACE=1), this build's timeline renders.
grep -h "^== \|^GPU passes\|^  [a-z:_ ]* [0-9]* *[0-9.]* *[0-9.]* *[0-9.]*%$" "$out/gpu_timeline.log" 2>/dev/null | tr -s ' ' | cut -c1-90
tail -5 "$out/cores_check.log" 2>/dev/null
tail -2 "$out/gpu_tests.log" 2>/dev/null
grep -h "a GPU render's\|wall.*for the GPU" "$out/prepare_planes.log" 2>/dev/null
