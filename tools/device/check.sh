#!/usr/bin/env bash
# The device checks, one call each (run on the lent GPU machine in the repository root, after
# tools/device/prepare.sh here; the run tool's command `bash tools/device/check.sh`, carry
# [".dev"]):
#   MODE=basic (default)  kernel parity, then issue 20's figures at 128³ (bench plenoxels, bench
#                         surface); about 7.5 minutes at most, seconds to a minute on a GPU.
#   MODE=accuracy         issue 19 at 512³: `bench accuracy --res 512` on the scenes in
#                         .dev/data (9 minutes at most; resumable on the same warm machine).
#   MODE=all              one call for a 15-minute lease: basic's steps with tighter limits,
#                         then `bench accuracy --res 512` on the first scene in .dev/data
#                         (ACC_S seconds, default 300), then `train --stage surface --preset
#                         paper` from that scene's 512³ stage 1 (PAPER_S seconds, default 150;
#                         its log's "step" lines carry the rays/s reached). At most 9.5 minutes.
#   MODE=set              one call for a 15-minute lease when the 512³ set is what is missing:
#                         parity and the 128³ benches, then `bench accuracy --res 512` on every
#                         scene in .dev/data (ACC_S seconds, default 420), then the paper stage 1
#                         below on the first scene for what is left of BUDGET_S (default 540;
#                         skipped under 30 s). Order the scenes by name in .dev/data.
#   MODE=paper_stage1     `train --stage plenoxels --preset paper --res 512` on the first scene
#                         (128k steps of 5000 rays), PAPER1_S seconds (default 540); a later call
#                         on the same warm machine resumes it from its last checkpoint.
# ACC_FLAGS adds flags to `bench accuracy` (e.g. ACC_FLAGS="--batch 4096": stage 1 with the
# batch `fast` used at 512³ before 7a7d55b; `--surface-set batch=N` sets stage 2's alone); its
# output folder is named after them, so runs with other flags are not reused.
# Each step has its own time limit, so one that hangs leaves the others their time. What comes
# back is $OUT/NAME.log per step (the commands with --json print their JSON object as the log's
# last line), the 512³ accuracy.json and $OUT/summary.txt: at most seven files, under the tool's
# eight. Without an NVIDIA driver it runs on whatever Vulkan device there is (a dry run here on
# lavapipe: OUT=/tmp/out bash tools/device/check.sh).
set -uo pipefail
cd "$(dirname "$0")/../.."
OUT=${OUT:-/tmp/device-out}
mkdir -p "$OUT"
bin=.dev/alphasurf
[ -x "$bin" ] || { echo "no $bin: run tools/device/prepare.sh first and carry .dev" >&2; exit 2; }
if ! ldconfig -p | grep -q libvulkan.so.1; then
  for f in .dev/debs/*.deb; do dpkg -x "$f" /; done
  ldconfig
fi
icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
[ -f "$icd" ] && export VK_DRIVER_FILES=$icd
summary=$OUT/summary.txt
: >"$summary"
# step NAME SECONDS COMMAND...: runs COMMAND with its output in $OUT/NAME.log, and records its
# exit status and wall time in the summary.
step() {
  local name=$1 limit=$2
  shift 2
  local t0=$SECONDS
  timeout "$limit" "$@" >"$OUT/$name.log" 2>&1
  local rc=$?
  echo "$name: exit $rc in $((SECONDS - t0)) s" | tee -a "$summary"
  return $rc
}
acc_out=/tmp/acc512$(printf %s "${ACC_FLAGS:-}" | tr -cd 'a-z0-9')
case "${MODE:-basic}" in
basic)
  step devices 30 "$bin" devices
  step parity 120 "$bin" check-kernels --json
  step bench_plenoxels 150 "$bin" bench plenoxels --json --steps 48
  step bench_surface 150 "$bin" bench surface --json --steps 48 --rounds 1
  ;;
accuracy)
  # Stage 1, the level sweep, stage 2, extract and eval per scene; a scene finished in an
  # earlier call on the same machine is not redone.
  step accuracy_512 540 "$bin" bench accuracy --data .dev/data/*/ --res 512 --backend vulkan \
    --out "$acc_out" ${ACC_FLAGS:-} --json
  cp "$acc_out/accuracy.json" "$OUT/accuracy_512.json" 2>/dev/null
  ;;
all)
  step parity 90 "$bin" check-kernels --json
  step bench_plenoxels 60 "$bin" bench plenoxels --json --steps 48
  step bench_surface 60 "$bin" bench surface --json --steps 48 --rounds 1
  scene=$(ls -d .dev/data/*/ | head -1)
  name=$(basename "$scene")
  step accuracy_512 "${ACC_S:-300}" "$bin" bench accuracy --data "$scene" --res 512 \
    --backend vulkan --out "$acc_out" ${ACC_FLAGS:-} --json
  cp "$acc_out/accuracy.json" "$OUT/accuracy_512.json" 2>/dev/null
  category=${name%%_*}
  step paper_stage2_512 "${PAPER_S:-150}" "$bin" train --stage surface \
    --init "$acc_out/$name/plenoxels" --data "$scene" --out /tmp/paper_s2 \
    --category "$category" --preset paper --backend vulkan --overwrite
  ;;
set)
  step parity 90 "$bin" check-kernels --json
  step bench_plenoxels 60 "$bin" bench plenoxels --json --steps 48
  step bench_surface 60 "$bin" bench surface --json --steps 48 --rounds 1
  step accuracy_512 "${ACC_S:-420}" "$bin" bench accuracy --data .dev/data/*/ --res 512 \
    --backend vulkan --out "$acc_out" ${ACC_FLAGS:-} --json
  cp "$acc_out/accuracy.json" "$OUT/accuracy_512.json" 2>/dev/null
  left=$((${BUDGET_S:-540} - SECONDS))
  if [ "$left" -ge 30 ]; then
    step paper_stage1_512 "$left" "$bin" train --stage plenoxels --preset paper --res 512 \
      --data "$(ls -d .dev/data/*/ | head -1)" --out /tmp/paper_s1 --backend vulkan --overwrite
  fi
  ;;
paper_stage1)
  scene=$(ls -d .dev/data/*/ | head -1)
  again=--overwrite
  [ -f /tmp/paper_s1/plenoxels.npz ] && again=--resume
  step paper_stage1_512 "${PAPER1_S:-540}" "$bin" train --stage plenoxels --preset paper \
    --res 512 --data "$scene" --out /tmp/paper_s1 --backend vulkan $again
  ;;
*)
  echo "MODE is basic, accuracy, all, set or paper_stage1, not ${MODE}" >&2
  exit 2
  ;;
esac
