#!/usr/bin/env bash
# Deterministic training runs for checking that a change leaves behaviour unchanged: both stages
# on the CPU backend with one thread on the built-in thin scene (stage 1 + stage 2; a translucent
# stage 2 counted per structure; a stage 1 stopped at 150 steps and resumed to 300). Prints the
# md5 of every trained grid's arrays (the .npz members but the metadata, which holds the
# configuration: a new configuration field changes no array); run it with the binaries before and
# after a change and diff.
#   usage: bash tools/same_grids.sh BINARY OUT_DIR
# Build the binary with a plain `cargo build --release` first: the `--features fused` test build
# of tools/test.sh leaves a binary whose stage 2 differs.
set -euo pipefail
B=$(realpath "$1"); O=$2
rm -rf "$O"; mkdir -p "$O"
export RAYON_NUM_THREADS=1
S=$O/scene
"$B" make-scene --kind thin --out "$S" > /dev/null
"$B" train --stage all --data "$S" --out "$O/all" --backend cpu --res 64 --iters 300 \
  --surface-iters 200 --batch 1024 > "$O/all.log" 2>&1
"$B" train --stage surface --init "$O/all/plenoxels" --data "$S" --out "$O/s2struct" \
  --backend cpu --category translucent --surface-iters 120 --batch 1024 \
  --set truncation_count='"structure"' > "$O/s2struct.log" 2>&1
"$B" train --stage plenoxels --data "$S" --out "$O/resumed" --backend cpu --res 64 --iters 150 \
  --batch 1024 > "$O/resumed.log" 2>&1
"$B" train --stage plenoxels --data "$S" --out "$O/resumed" --resume --iters 300 \
  --backend cpu >> "$O/resumed.log" 2>&1
(cd "$O" && find . -name '*.npz' -not -path './scene/*' | sort | python3 -c '
import hashlib, sys, zipfile
for path in sys.stdin.read().split():
    z = zipfile.ZipFile(path)
    h = hashlib.md5()
    for name in sorted(z.namelist()):
        if name != "alphasurf_meta.npy":
            h.update(name.encode() + z.read(name))
    print(h.hexdigest(), path)
')
