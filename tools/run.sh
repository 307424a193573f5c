#!/usr/bin/env bash
# The main job on a fresh machine: set up, build, and run the end-to-end αSurf demo on the built-in
# thin scene: make-scene → stage 1 (Plenoxels, preset fast) → Plenoxels level-set sweep → stage 2
# (αSurf) → extraction → evaluation, then a table and runs/demo-thin/report.md with PNGs.
# On a GPU the kernels run through Vulkan; on a machine without one, the CPU twins (faster than
# lavapipe there; `--backend vulkan` forces lavapipe).
# Extra arguments go to `alphasurf demo` (e.g. --fast, --scene translucent, --backend cpu).
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
cargo build --release --locked
./target/release/alphasurf demo --out runs/demo-thin "$@"
