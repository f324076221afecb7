#!/usr/bin/env bash
# Issue 13's GPU figures in one go, on a lent GPU machine after tools/gpu-run.sh has unpacked
# the examples into /tmp/bin: the passes' GPU time per frame and per part at 1920×1080 with
# the 20 k budget (the light moving every frame, and still), the same room with the plugin off
# (what the plugin adds to a frame: "GPU time of all timed spans" in each log; with and
# without the depth and normal prepass it asks for), the diffusion
# profile alone (no beam table), the gather at full resolution and a cap of 2 products.
# As Bevy's release builds run it: wgpu's indirect-call validation off. The first run builds
# the transport and keeps it in $CACHE; the others load it. PRECOMPUTE=1 also times
# `translucent_precompute --budgets $PATCHES --beam-table` (and its release build where
# carried as translucent_precompute_release) on this machine's cores.
#
# Here:   bash tools/gpu-pack.sh translucent [translucent_precompute]
# There:  bash tools/gpu-run.sh bash tools/translucency-h100.sh
# Smaller (to try it on the software driver): SIZE=384x288 PATCHES=500 BIN=target/debug/examples
set -u
BIN=${BIN:-/tmp/bin}
SIZE=${SIZE:-1920x1080}
PATCHES=${PATCHES:-20000}
FRAMES=${FRAMES:-100}
OUT=${OUT:-/tmp/translucency-h100}
CACHE=${CACHE:-$OUT/cache}
mkdir -p "$OUT"
export WGPU_VALIDATION_INDIRECT_CALL=0
echo "cores: $(nproc)"
if [ "${PRECOMPUTE:-0}" = 1 ]; then
  for build in translucent_precompute translucent_precompute_release; do
    [ -x "$BIN/$build" ] || continue
    echo "$build, budget $PATCHES:"
    timeout 300 "$BIN/$build" --budgets "$PATCHES" --beam-table 2>&1 | grep -E 'beam table|^[0-9]'
  done
fi
run() {
  local name=$1
  shift
  timeout 240 "$BIN/translucent" --headless --size "$SIZE" --patches "$PATCHES" --frames "$FRAMES" \
    --cache-dir "$CACHE" --out "$OUT/$name" "$@" > "$OUT/$name.log" 2>&1
  echo "== $name ($*, exit $?)"
  grep -E 'patches,|average time|GPU time' "$OUT/$name.log"
}
run table_moving_1 --swing
run table_moving_2 --swing
run table_still
run off_moving --swing --translucency false
run off_prepass_moving --swing --translucency false --prepass
run table_moving_cap2 --swing --max-iterations 2
run profile_moving --swing --beam-table false
run table_moving_full --swing --gather-resolution full
# The lights' maps gone (the CPU's shadow rays inject): no march, single scattering in the
# table; the gather's time against table_moving_* is what the march costs (a new table: the
# first run of this builds it).
run shadow_rays_moving --swing --injection shadow-rays
