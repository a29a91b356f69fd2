#!/usr/bin/env bash
# What a mip pyramid costs against level 0, and what the coarser levels'
# tolerance policy trades: the figures of docs/dsm-build.md and
# docs/dsm-convert.md ("Mip pyramids").
#
#   bench/pyramid_cost.sh BUILD_DIR
#
# For every example scene (dsm-build at its own resolution, 16 spp) and for a
# sparse camera-like deep image (exr_check_helper make-render: 0 to 2 samples a
# pixel, imported with dsm-convert), one row per policy: the level-tolerance
# factor (0.5 is the default: every level's stated bound stays within twice
# the tolerance; 1 keeps the tolerance, the bound grows by one tolerance per
# level) and a cap on the levels. Prints Markdown tables: bytes of level 0,
# of the whole pyramid, their ratio, and the coarsest level's stated bound.
set -euo pipefail
build=$(realpath "$1")
here=$(cd "$(dirname "$0")/.." && pwd)
work=$(mktemp -d "${TMPDIR:-/tmp}/dsm-pyramid.XXXXXX")
trap 'rm -rf "$work"' EXIT

row() {  # row LABEL MAP
  "$build/tools/dsm-info" --json "$2" | /usr/bin/python3 -c '
import json, sys
d = json.load(sys.stdin)
levels = d["levels"]
level0 = levels[0]["stored_bytes"]
pyramid = sum(l["stored_bytes"] for l in levels)
print("| %s | %d | %d | %d | %.2f | %.4g / %.4g |" % (sys.argv[1], len(levels), level0, pyramid, pyramid / level0,
      levels[0]["error_bound"], levels[-1]["error_bound"]))' "$1"
}

header() {
  echo
  echo "| $1 | levels | level 0, bytes | all levels, bytes | ratio | bound: level 0 / coarsest |"
  echo "|---|---:|---:|---:|---:|---:|"
}

header "example, 16 spp, factor"
for scene in "$here"/examples/*.json; do
  name=$(basename "$scene" .json)
  for factor in 0.5 1; do
    "$build/tools/dsm-build" "$scene" -o "$work/$name.dsm" -s 16 --level-tolerance-factor "$factor" -q
    row "$name, $factor" "$work/$name.dsm"
  done
done

"$build/tests/exr_check_helper" make-render "$work/render.exr" 512 512 >/dev/null
header "sparse camera image 512², policy"
for policy in "0.5" "1" "2" "0.5 -m 4" "0.5 -m 2" "0.5 -m 1"; do
  read -r factor cap <<<"$policy"
  # shellcheck disable=SC2086
  "$build/tools/dsm-convert" "$work/render.exr" "$work/render.dsm" --ortho-width 1 \
    --level-tolerance-factor "$factor" $cap -q
  row "factor $factor${cap:+, levels ${cap#-m }}" "$work/render.dsm"
done
