#!/usr/bin/env bash
# Re-checks issue 43's figures in a checkout of alphasurf (run from its root).
# 1. Distinct identical lines two stage files share, as the issue counts them: lines stripped of
#    indentation, leaving out blank lines, comments (//...), lines of braces/brackets/punctuation
#    only, and `use` lines; "plain" = all non-blank stripped lines.
# 2. Line totals of the stage loops, backends (cpu.rs, vulkan.rs, mod.rs) and pipeline entries at
#    51bdae5 against their successors now.
set -euo pipefail
shared() {
python3 - "$1" "$2" <<'PY'
import re, sys
def lines(text, strict):
    out = set()
    for raw in text.splitlines():
        s = raw.strip()
        if not s: continue
        if strict and (s.startswith("//") or re.fullmatch(r"[{}()\[\];,.]+", s)
                       or re.match(r"(pub(\([a-z]+\))? )?use ", s)):
            continue
        out.add(s)
    return out
a, b = (open(p).read() for p in sys.argv[1:3])
print(len(lines(a, True) & lines(b, True)), "(plain", str(len(lines(a, False) & lines(b, False))) + ")")
PY
}
echo "== distinct identical lines (issue's count), now"
for p in "train/plenoxels_steps train/surface_steps" "plenoxel/vulkan surface/vulkan" \
         "plenoxel/cpu surface/cpu" "plenoxel/mod surface/mod" "plenoxel/plan surface/plan" \
         "pipeline/train_plenoxels pipeline/train_surface" "plenoxel/cpu surface/vulkan" \
         "plenoxel/vulkan surface/cpu"; do
  set -- $p; echo "$(shared src/$1.rs src/$2.rs)  $1 ~ $2"
done
echo "== the same at 51bdae5 (stage1/stage2 names then)"
t=$(mktemp -d)
for f in train/stage1 train/stage2 plenoxel/vulkan surface/vulkan plenoxel/cpu surface/cpu plenoxel/mod surface/mod pipeline/train_stage1 pipeline/train_stage2; do
  mkdir -p "$t/$(dirname $f)"; git show 51bdae5:src/$f.rs > "$t/$f.rs"; done
for p in "train/stage1 train/stage2" "plenoxel/vulkan surface/vulkan" "plenoxel/cpu surface/cpu" \
         "plenoxel/mod surface/mod" "pipeline/train_stage1 pipeline/train_stage2"; do
  set -- $p; echo "$(shared $t/$1.rs $t/$2.rs)  $1 ~ $2"
done
echo "== lines: 51bdae5 -> now (wc -l)"
o=0; n=0; o2=0; n2=0
for s in plenoxel surface; do for f in cpu vulkan mod; do
  a=$(git show 51bdae5:src/$s/$f.rs | wc -l); b=$(wc -l < src/$s/$f.rs); o=$((o+a)); n=$((n+b))
  [ $f != mod ] && { o2=$((o2+a)); n2=$((n2+b)); }; echo "  $a -> $b  $s/$f.rs"; done; done
for p in "train/stage1 train/plenoxels_steps" "train/stage2 train/surface_steps" \
         "pipeline/train_stage1 pipeline/train_plenoxels" "pipeline/train_stage2 pipeline/train_surface"; do
  set -- $p; a=$(git show 51bdae5:src/$1.rs | wc -l); b=$(wc -l < src/$2.rs)
  o=$((o+a)); n=$((n+b)); o2=$((o2+a)); n2=$((n2+b)); echo "  $a -> $b  $1.rs -> $2.rs"; done
echo "  total with the backends' mod.rs: $o -> $n ($((n-o)))"
echo "  total without mod.rs:            $o2 -> $n2 ($((n2-o2)))"
echo "== duplicates: pairs between the two stages' files"
duplicates --most 200 --seconds 60 | grep -E "src/(plenoxel|surface)/[a-z_]*\.rs.*~ src/(plenoxel|surface)/|train/(plenoxels|surface)_steps.*~|pipeline/train_(plenoxels|surface).*~" \
  | awk '{ split($2,a,"/"); split($4,b,"/"); if (a[2]!=b[2] || $2 ~ /_steps|pipeline/) print }' || true
rm -rf "$t"
