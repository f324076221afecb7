#!/usr/bin/env bash
# Issue 13's GPU figures in one go, on a lent GPU machine after tools/gpu-run.sh has unpacked
# the examples into /tmp/bin: the precompute of the issue's 20 k budget with and without the
# beam table (this machine's cores), and the passes' GPU time per frame at 1920×1080 with the
# light moving every frame and with it still, without and with the beam table (its exit lobes
# on, the default), warm-started (the default) and, moving without the table, cold. As Bevy's
# release builds run it: wgpu's indirect-call validation off.
#
# Here:   bash tools/gpu-pack.sh translucent translucent_precompute
# There:  bash tools/gpu-run.sh bash tools/translucency-h100.sh
# Smaller (to try it on the software driver): SIZE=384x288 PATCHES=500 BIN=target/debug/examples
set -u
BIN=${BIN:-/tmp/bin}
SIZE=${SIZE:-1920x1080}
PATCHES=${PATCHES:-20000}
FRAMES=${FRAMES:-100}
OUT=${OUT:-/tmp/translucency-h100}
mkdir -p "$OUT"
export WGPU_VALIDATION_INDIRECT_CALL=0
echo "cores: $(nproc)"
echo "precompute, budget $PATCHES:"
timeout 300 "$BIN/translucent_precompute" --budgets "$PATCHES" --beam-table 2>&1 | grep -E 'beam table|^[0-9]'
for table in "" "--beam-table"; do
  for motion in "--swing" ""; do
    name="table${table:+_on}${motion:+_moving}"
    timeout 240 "$BIN/translucent" --headless --size "$SIZE" --patches "$PATCHES" --frames "$FRAMES" \
      $motion $table --out "$OUT/$name" > "$OUT/$name.log" 2>&1
    echo "${table:-no table} ${motion:-lights still}: $(grep -E 'precomputed|average' "$OUT/$name.log" | tr '\n' ' ')"
  done
done
# The warm start's A/B (TranslucencySettings::warm_start; on above): the light moving, cold.
timeout 240 "$BIN/translucent" --headless --size "$SIZE" --patches "$PATCHES" --frames "$FRAMES" \
  --swing --warm-start false --out "$OUT/cold_moving" > "$OUT/cold_moving.log" 2>&1
echo "no table, light moving, cold starts: $(grep -E 'precomputed|average' "$OUT/cold_moving.log" | tr '\n' ' ')"
