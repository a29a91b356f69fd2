#!/usr/bin/env bash
# The farm figures of docs/dsm-farm.md: one map built on this machine by
# dsm-build, then as parts through a one-node Slurm cluster on localhost
# (tests/tools/slurm_local_cluster.sh, one slot per core, one thread per part),
# and the time each step takes.
#
#   bench/farm/slurm_farm.sh DSM_FARM DSM_BUILD SCENE RESOLUTION SPP PARTS
#   e.g. bench/farm/slurm_farm.sh build/tools/dsm-farm build/tools/dsm-build examples/hairball.json 512 64 16
#
# Prints a Markdown table: the wall times, their ratio, the one-machine CPU time, the parts' own build
# time (from their logs), the stitch, and the overhead per part (submission,
# scheduling, start: the slot time not spent building, per part), the bytes of
# the parts and of the map. Needs munged, slurmctld, slurmd (scripts/install-deps).
set -euo pipefail
farm=$(realpath "$1") build=$(realpath "$2") scene=$(realpath "$3") resolution=$4 spp=$5 parts=$6
PATH=$PATH:/usr/sbin
source "$(dirname "$0")/../../tests/tools/slurm_local_cluster.sh"
slots=$(nproc)
start_slurm_cluster "$slots" >/dev/null

seconds() { date +%s.%N; }
options=(-r "$resolution" -s "$spp")

t0=$(seconds)
TIMEFORMAT='%U %S'
{ time "$build" "$scene" -o "$root/one.dsm" "${options[@]}" -j "$slots" -q; } 2>"$root/one.cpu"
t1=$(seconds)
"$farm" submit --engine slurm "$scene" -o "$root/farm.dsm" --tiles "$parts" "${options[@]}" --cpus-per-task 1 \
  --threads 1 --wait -q >/dev/null
t2=$(seconds)
cmp "$root/one.dsm" "$root/farm.dsm"
{ time "$farm" stitch "$root/farm.dsm.parts" -o "$root/again.dsm" -q; } 2>"$root/stitch.cpu"
t3=$(seconds)

part_seconds=$(sed -n 's/.* in \([0-9.]*\) s (process CPU.*/\1/p' "$root"/farm.dsm.parts/logs/part-*.log | paste -sd+ | bc -l)
part_cpu=$(sed -n 's/.*(process CPU \([0-9.]*\) s)$/\1/p' "$root"/farm.dsm.parts/logs/part-*.log | paste -sd+ | bc -l)
part_bytes=$(cat "$root"/farm.dsm.parts/part-*.dsm | wc -c)
map_bytes=$(wc -c <"$root/one.dsm")
awk -v one="$(echo "$t1 - $t0" | bc -l)" -v farm="$(echo "$t2 - $t1" | bc -l)" \
    -v stitch="$(echo "$t3 - $t2" | bc -l)" -v parts="$parts" -v slots="$slots" -v built="$part_seconds" \
    -v part_bytes="$part_bytes" -v map_bytes="$map_bytes" -v res="$resolution" -v spp="$spp" \
    -v one_cpu="$(awk '{print $1 + $2}' "$root/one.cpu")" -v stitch_cpu="$(awk '{print $1 + $2}' "$root/stitch.cpu")" \
    -v part_cpu="$part_cpu" 'BEGIN {
  overhead = ((farm - stitch) * slots - built) / parts
  printf "| %s² at %s spp, %d parts, %d slots | value |\n|---|---:|\n", res, spp, parts, slots
  printf "| one-machine build (dsm-build -j %d), wall | %.1f s |\n", slots, one
  printf "| farm build (submit --wait, stitch included), wall | %.1f s |\n", farm
  printf "| one-machine build, CPU time (user + system) | %.1f s |\n", one_cpu
  printf "| ratio farm / one machine, wall | %.2f |\n", farm / one
  printf "| parts building (their own wall, one thread each), summed | %.1f s |\n", built
  printf "| parts, process CPU time summed (scene read and hash included) | %.1f s |\n", part_cpu
  printf "| CPU ratio parts / one machine | %.3f |\n", part_cpu / one_cpu
  printf "| stitch (dsm-farm stitch, measured alone), wall | %.2f s |\n", stitch
  printf "| stitch, CPU time (user + system) | %.2f s |\n", stitch_cpu
  printf "| overhead per part (slot time not building) | %.2f s |\n", overhead
  printf "| parts, bytes | %d |\n| map, bytes | %d |\n", part_bytes, map_bytes
}'
echo "byte-identical: yes"
