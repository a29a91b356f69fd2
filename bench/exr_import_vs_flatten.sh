#!/bin/bash
# CPU time of `dsm-convert IN.exr OUT.dsm --fov 60` against `oiiotool IN.exr --flatten` on the same deep
# renders (bench/COMPONENTS.md, "Deep EXR import"): per file, the least user + system time (all threads)
# of 3 runs of each, alternated, and their ratio. CPU time rather than wall time: a shared machine's
# wall times move by several times within minutes.
#
#   bench/exr_import_vs_flatten.sh DSM_CONVERT EXR_CHECK_HELPER WORK_DIR [dsm-convert options...]
set -u
convert=$1 helper=$2 work=$3
shift 3
mkdir -p "$work"
cpu() {
    /usr/bin/time -f "%U %S" -o "$work/time.txt" "$@" >/dev/null 2>&1
    local status=$?
    tail -n 1 "$work/time.txt" | awk '{print $1 + $2}'  # the last line: a failure adds one before it
    return $status
}
for tile in 0 64 128; do
    input="$work/render_$tile.exr"
    [ -f "$input" ] || "$helper" make-render "$input" 1024 1024 $([ $tile -gt 0 ] && echo $tile)
    best_import=999 best_flatten=999 note=""
    for run in 1 2 3; do
        t=$(cpu "$convert" "$input" "$work/out.dsm" --fov 60 -q "$@") || note="(the import fails)"
        best_import=$(echo "if ($t < $best_import) $t else $best_import" | bc)
        t=$(cpu oiiotool "$input" --flatten -o "$work/flat.exr")
        best_flatten=$(echo "if ($t < $best_flatten) $t else $best_flatten" | bc)
    done
    printf "%s: import %.2f s, flatten %.2f s, ratio %.2f %s\n" "$(basename "$input")" "$best_import" \
        "$best_flatten" "$(echo "$best_import / $best_flatten" | bc -l)" "$note"
done
