#!/usr/bin/env bash
# The main job on a fresh machine: set up, build, and run the kernel parity table on the Vulkan
# device (the end-to-end demo replaces this once training lands). Extra arguments go to the command.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
cargo build --release --locked
./target/release/alphasurf check-kernels "$@"
