#!/usr/bin/env bash
# Runs dsm-farm through a real Slurm (docs/dsm-farm.md): starts munged,
# slurmctld and slurmd on localhost under a fresh temporary directory (every
# file the daemons write is in it; ports chosen free; traffic on loopback),
# runs the checks, and stops the daemons by PID.
#
#   check_dsm_farm_slurm.sh DSM_FARM DSM_BUILD SCENE
#
# Checks (one cluster for all, to keep the time small):
#   identical  a 4x4 farm build equals the one-machine build byte for byte;
#   failure    a part made to fail (its output path is a directory) gives a
#              non-zero --wait naming it and no output; resubmitting that part
#              alone, then the stitch, completes the same map.
# Exit 77 (skipped) when Slurm or munge is not installed (scripts/install-deps).
set -euo pipefail
farm=$1 build=$2 scene=$3
for daemon in munged slurmctld slurmd sbatch scontrol sinfo; do
  command -v "$daemon" >/dev/null || PATH=$PATH:/usr/sbin
  command -v "$daemon" >/dev/null || { echo "SKIP: $daemon is not installed"; exit 77; }
done

source "$(dirname "$0")/slurm_local_cluster.sh"
fail() { echo "FAIL: $*"; exit 1; }
# 16 slots, more than the cores (config_overrides): the parts of the test map
# are small, and a scheduling cycle takes longer than one of them.
start_slurm_cluster 16

options=(-r 128 -t 16 -s 4)
"$build" "$scene" -o "$root/one.dsm" "${options[@]}" -q

# identical
start=$SECONDS
"$farm" submit --engine slurm "$scene" -o "$root/farm.dsm" --tiles 16 "${options[@]}" --cpus-per-task 1 --wait \
  >"$root/identical.out" 2>&1 || { cat "$root/identical.out"; fail "identical: the farm build failed"; }
cmp "$root/one.dsm" "$root/farm.dsm" || fail "identical: the farm build differs from the one-machine build"
grep -q "submitted parts job [0-9]*, stitch job [0-9]*" "$root/identical.out" || fail "identical: no job ids printed"
echo "identical: passed ($((SECONDS - start)) s)"

# failure
start=$SECONDS
mkdir -p "$root/failing.parts/part-0005.dsm"  # part 5 cannot be written
status=0
"$farm" submit --engine slurm "$scene" -o "$root/failing.dsm" --parts "$root/failing.parts" --tiles 16 \
  "${options[@]}" --cpus-per-task 1 --wait >"$root/failure.out" 2>&1 || status=$?
cat "$root/failure.out"
[ "$status" -ne 0 ] || fail "failure: --wait exited 0 with a failed part"
grep -q "parts failed: 5 " "$root/failure.out" || fail "failure: the failed part is not named"
grep -q "stitch CANCELLED" "$root/failure.out" || fail "failure: the stitch was not reported cancelled"
[ ! -e "$root/failing.dsm" ] || fail "failure: an output was written"
grep -q "is a directory\|directory" "$root/failing.parts/logs/part-0005.log" || fail "failure: part 5's log lacks the cause"
rmdir "$root/failing.parts/part-0005.dsm"
"$farm" submit --engine slurm "$scene" -o "$root/failing.dsm" --parts "$root/failing.parts" --tiles 16 \
  "${options[@]}" --cpus-per-task 1 --indices 5 --wait >"$root/resubmit.out" 2>&1 ||
  { cat "$root/resubmit.out"; fail "failure: the resubmission failed"; }
cmp "$root/one.dsm" "$root/failing.dsm" || fail "failure: the completed build differs from the one-machine build"
built=$(grep -l "wrote part" "$root"/failing.parts/logs/part-*.log | wc -l)
[ "$built" -eq 16 ] || fail "failure: $built part logs say built, expected 16 (15 first, then part 5)"
echo "failure: passed ($((SECONDS - start)) s)"
