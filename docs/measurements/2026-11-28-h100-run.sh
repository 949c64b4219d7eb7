#!/usr/bin/env bash
# The device run of 2026-11-28: `fogplanes devices`, scripts/gpu_check.sh, scripts/cores_check.sh
# and the GPU tests (tests/gpu.rs, tests/devices.rs) on the device's driver, in one call. Carried:
# target/release/fogplanes, .gl/ (the Vulkan loader's packages, scripts/gpu_check.sh --fetch) and
# the release test binary as .gl/all (`cargo test --release --no-run`), which finds the repo at
# the path it was built in (/work/main), linked to the copy there.
cd "$(dirname "$0")/../.."
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
B=target/release/fogplanes
{ date -u; nvidia-smi; $B devices; } 2>&1 | tee "$OUT/devices.log"
timeout 200 bash scripts/gpu_check.sh >/dev/null 2>&1; echo "gpu_check rc $?" >> "$OUT/gpu_check.log"
timeout 240 bash scripts/cores_check.sh "$B" 2>&1 | tee "$OUT/cores_check.log"; echo "cores_check rc ${PIPESTATUS[0]}" >> "$OUT/cores_check.log"
[ -e /work/main ] || { mkdir -p /work && ln -s "$PWD" /work/main; }
{ date -u; FOGPLANES_REQUIRE_GPU=1 timeout 150 .gl/all --test-threads 4 gpu:: devices::; echo "gpu tests rc $?"; date -u; } 2>&1 | tee "$OUT/gpu_tests.log"
