#!/usr/bin/env bash
# Issue 13's GPU figures in one go, on a lent GPU machine after tools/gpu-run.sh has unpacked
# the examples into /tmp/bin: the precompute of the issue's 20 k budget with and without the
# beam table (this machine's cores), and the passes' GPU time per frame at 1920×1080 with the
# light moving every frame and with it still, without the beam table at both gather
# resolutions, with it (its exit lobes on, the default) at the default one. As Bevy's release
# builds run it: wgpu's indirect-call validation off. A release build of the precompute, where
# carried as translucent_precompute_release, is timed too.
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
if [ -x "$BIN/translucent_precompute_release" ]; then
  echo "precompute (release build), budget $PATCHES:"
  timeout 300 "$BIN/translucent_precompute_release" --budgets "$PATCHES" --beam-table 2>&1 | grep -E 'beam table|^[0-9]'
fi
# Without the table both gather resolutions (GatherResolution; half the default), the light
# moving twice over (A/B pairs on the same machine), with it the default alone.
for table in "--beam-table false" "--beam-table true"; do
  motions='--swing "" --swing'
  resolutions="half full"
  if [ "$table" = "--beam-table true" ]; then motions='--swing ""'; resolutions=half; fi
  eval "set -- $motions"
  run=0
  for motion in "$@"; do
    run=$((run + 1))
    for resolution in $resolutions; do
      name="table_${table##* }${motion:+_moving}_${resolution}_$run"
      timeout 240 "$BIN/translucent" --headless --size "$SIZE" --patches "$PATCHES" --frames "$FRAMES" \
        $motion $table --gather-resolution "$resolution" --out "$OUT/$name" > "$OUT/$name.log" 2>&1
      echo "${table} ${motion:-lights still} gather $resolution: $(grep -E 'precomputed|average' "$OUT/$name.log" | tr '\n' ' ')"
    done
  done
done
