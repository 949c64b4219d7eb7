#!/usr/bin/env bash
# The timeline run of 2026-11-28 (second call): the build of 8af1bf7 with timeline probes
# (a span printed on stderr per step when FOGPLANES_TRACE=1; crates/core/src/trace.rs came
# after, with the probes renamed), carried as target/release/fogplanes with .gl/; it ran as
# .gl/trace_run.sh (hence the `cd` to the folder above its own).
cd "$(dirname "$0")/.."
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
B=target/release/fogplanes; S=media_scenes/six_lights.toml
run() { echo "== $*"; FOGPLANES_TRACE=1 timeout 60 $B render $S --resolution 640x360 -q -o /tmp/t.exr "$@" 2>&1 | grep -v '^wrote'; }
{ date -u
for e in smis-exact cmis-exact unweighted; do run --planes 40960 -e $e --device gpu; run --planes 40960 -e $e --device gpu; done
run --planes 655360 -e smis-exact --device gpu; run --planes 655360 -e smis-exact --device gpu
run --planes 40960 -e smis-exact
date -u; } > "$OUT/trace.log" 2>&1
grep -E "^==|smis-exact:|cmis-exact:|unweighted:|Gpu::new|pipeline|prepare first|emission" "$OUT/trace.log" | head -80
