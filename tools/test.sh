#!/usr/bin/env bash
# The test command: set up the machine, then build and run every test. GPU parity tests run on
# the Vulkan device (lavapipe here); with no Vulkan device they fail, never skip.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
# In CI (no GPU) pin lavapipe: the loader then skips probing other drivers.
if [ -n "${CI:-}" ] && [ -z "${VK_DRIVER_FILES:-}" ]; then
  export VK_DRIVER_FILES=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json
fi
cargo build --release --locked
./target/release/alphasurf devices
cargo test --release --locked --tests -- --test-threads 2
# The twins' decision paths with a·b + c contracted (math::madd, feature `fused`): the DDA, cubic
# and surface-hit tests and parity rows must pass unchanged (issue 21; one extra build).
cargo test --release --locked --features fused --test kernels -- --test-threads 2 \
  dda:: cubic:: surface_fwd:: parity::dda_walk parity::cubic_solve parity::extract_points \
  parity::surface_fwd parity::surface_faces parity::surface_train
