#!/usr/bin/env bash
# Builds the named examples (dev profile: dependencies are optimised), strips them and packs
# them xz-compressed into .dev/ (ignored by git) for tools/gpu-run.sh on a lent GPU machine.
set -eu
mkdir -p .dev
rm -f .dev/*.xz
for example in "$@"; do
  cargo build -q --example "$example"
  strip -o ".dev/$example" "target/debug/examples/$example"
  xz -T2 -6 -f ".dev/$example"
done
ls -la .dev
