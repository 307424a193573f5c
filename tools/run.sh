#!/usr/bin/env bash
# The main job on a fresh machine: set up, build, generate the built-in thin scene (if not there
# yet) and train stage 1 (Plenoxels, preset fast) on the Vulkan device (lavapipe without a GPU).
# Writes runs/thin/ (dataset) and runs/thin-plenoxels/ (checkpoint, test renders, metrics.json).
# Extra arguments go to `alphasurf train` (e.g. --backend cpu, --iters 500).
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
cargo build --release --locked
bin=./target/release/alphasurf
[ -f runs/thin/transforms_train.json ] || $bin make-scene --kind thin --out runs/thin
$bin train --data runs/thin --out runs/thin-plenoxels --preset fast "$@"
