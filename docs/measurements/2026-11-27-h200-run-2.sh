#!/usr/bin/env bash
# The second device run of 2026-11-27 (not committed: .gl/ is ignored).
cd "$(dirname "$0")/.."
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
B=target/release/fogplanes
{ date -u; $B devices; } 2>&1 | tee "$OUT/devices.log"
timeout 150 bash scripts/gpu_check.sh >/dev/null 2>&1; echo "gpu_check (new) rc $?" >> "$OUT/gpu_check.log"
mkdir -p "$OUT/old"; OUT="$OUT/old" FOGPLANES=.gl/old/fogplanes timeout 120 bash scripts/gpu_check.sh >/dev/null 2>&1; echo "gpu_check (old) rc $?" >> "$OUT/old/gpu_check.log"
{
echo "forward fog (g = 0.85) on the GPU and the CPU, 640x400, 163,840 planes:"
for e in smis-exact cmis-exact unweighted; do
  for run in 1 2; do $B render media_scenes/forward_fog.toml --resolution 640x400 --planes 163840 -e $e --device gpu -q -o /tmp/ffg.exr 2>&1 | grep -v '^wrote'; done
  $B render media_scenes/forward_fog.toml --resolution 640x400 --planes 163840 -e $e -q -o /tmp/ffc.exr 2>&1 | grep -v '^wrote'
  printf 'agreement forward_fog %s: ' $e; $B compare /tmp/ffg.exr /tmp/ffc.exr | tr '\n' ' ' | tr -s ' '; echo
done
} 2>&1 | tee "$OUT/forward_fog.log"
{
echo "cores: $(nproc); smis-exact, six_lights 640x360; alternating 1 and 16 threads, 3 times each (bash time: wall user sys)"
TIMEFORMAT='%R %U %S'
for planes in 655360 2621440; do
  n=3; [ $planes = 2621440 ] && n=1
  for i in $(seq $n); do for t in 1 16; do
    printf '%s planes, %s threads: ' $planes $t
    { time $B render media_scenes/six_lights.toml -q --resolution 640x360 -e smis-exact --planes $planes --threads $t -o /tmp/c.exr >/dev/null 2>&1; } 2>&1
  done; done
done
date -u
} 2>&1 | tee "$OUT/cores_repeat.log"
