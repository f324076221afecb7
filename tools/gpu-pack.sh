#!/usr/bin/env bash
# Builds the named examples (dev profile: dependencies are optimised), strips them and packs
# them xz-compressed into .dev/ (ignored by git) for tools/gpu-run.sh on a lent GPU machine.
# RELEASE="example ..." also packs release builds of those, as `<example>_release` (the
# translucency's precompute is timed in both: tools/translucency-h100.sh).
set -eu
mkdir -p .dev
rm -f .dev/*.xz
for example in "$@"; do
  cargo build -q --example "$example"
  strip -o ".dev/$example" "target/debug/examples/$example"
  xz -T2 -6 -f ".dev/$example"
done
for example in ${RELEASE:-}; do
  cargo build -q --release --example "$example"
  strip -o ".dev/${example}_release" "target/release/examples/$example"
  xz -T2 -6 -f ".dev/${example}_release"
done
ls -la .dev
