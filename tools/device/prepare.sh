#!/usr/bin/env bash
# Prepares a run on a lent GPU machine (no Rust toolchain, no network there): builds the release
# binary and strips it into .dev/, downloads the Vulkan loader packages into .dev/debs/, and
# copies the development scenes named in $SCENES (default: thin_fan) into .dev/data/. .dev/ is
# ignored through .git/info/exclude and travels with `carry: [".dev"]` (64 MiB per call in all:
# the binary ~6 MB, the packages ~1 MB, a scene 16–23 MB).
# Then, on the device: bash tools/device/check.sh (see its header).
set -euo pipefail
cd "$(dirname "$0")/../.."
grep -qx '/.dev/' .git/info/exclude 2>/dev/null || echo '/.dev/' >>.git/info/exclude
mkdir -p .dev/debs .dev/data
cargo build --release
strip -o .dev/alphasurf target/release/alphasurf
if ! ls .dev/debs/libvulkan1_*.deb >/dev/null 2>&1; then
  apt-get update -qq
  (cd .dev/debs && apt-get download -qq libvulkan1 libglvnd0 libegl1 libgl1 libglx0 libopengl0 libgles2)
fi
for s in ${SCENES:-thin_fan}; do
  src=../shared/fixtures/$s
  [ -d "$src" ] || { echo "no development scene $src" >&2; exit 1; }
  rm -rf ".dev/data/$s"
  cp -r "$src" ".dev/data/$s"
done
du -sh .dev
echo "device run: command 'bash tools/device/check.sh', carry [\".dev\"]"
