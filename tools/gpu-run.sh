#!/usr/bin/env bash
# Runs the benches on a lent GPU machine (the tool library's `device`): unpacks the Vulkan
# loader carried in .gl/, the examples built here and carried xz-compressed in .dev/, and
# runs the command given (e.g. `bench --table presets`), its output kept under $OUT.
# Build here first:  tools/gpu-pack.sh bench volumetric_bench  (dev profile)
set -u
for f in .gl/*.deb; do dpkg -x "$f" /; done
ldconfig
if ! ldconfig -p | grep -q libvulkan; then echo "no Vulkan loader"; exit 1; fi
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
export BEVY_ASSET_ROOT="$PWD" RUST_LOG=warn
mkdir -p /tmp/bin
for f in .dev/*.xz; do
  python3 -c 'import lzma,sys; open(sys.argv[2],"wb").write(lzma.open(sys.argv[1]).read())' "$f" "/tmp/bin/$(basename "$f" .xz)"
done
chmod +x /tmp/bin/*
nvidia-smi --query-gpu=name,clocks.sm,clocks.max.sm,temperature.gpu --format=csv,noheader
"$@"
