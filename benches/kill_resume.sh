#!/usr/bin/env bash
# Kill a tracking run with SIGKILL at N random moments, resume it each time, and compare its
# tracks.json byte for byte with an uninterrupted run's. Usage:
#   benches/kill_resume.sh [N=10] [FRAMES=24] [SEED=1]
# Uses the release binary (built if needed) and a synthetic realistic capture in a temp folder.
set -euo pipefail
cd "$(dirname "$0")/.."
n=${1:-10} frames=${2:-24} seed=${3:-1}
cargo build --release --quiet
bin=$PWD/target/release/jawtrack
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
"$bin" synth "$work/c" --frames "$frames" --seed "$seed" >/dev/null
start=$(date +%s%N)
"$bin" track "$work/c" -o "$work/whole.json" --backend cpu >/dev/null 2>&1
took=$(awk -v a="$start" -v b="$(date +%s%N)" 'BEGIN { printf "%.2f", (b - a) / 1e9 }')
echo "uninterrupted: $frames frames in ${took} s"
same=0
for i in $(seq 1 "$n"); do
  out="$work/run$i.json"
  # A random moment within the run (the first second is mostly loading).
  at=$(awk -v s="$RANDOM" -v t="$took" 'BEGIN { srand(s); printf "%.2f", 0.3 + rand() * (t - 0.6) }')
  "$bin" track "$work/c" -o "$out" --backend cpu >/dev/null 2>&1 &
  pid=$!
  sleep "$at"
  kill -9 "$pid" 2>/dev/null || true
  wait "$pid" 2>/dev/null || true
  kept=$(($(wc -l <"$out.journal" 2>/dev/null || echo 1) - 1))
  "$bin" track "$work/c" -o "$out" --backend cpu --resume >/dev/null 2>&1
  if cmp -s "$work/whole.json" "$out"; then
    verdict=identical
    same=$((same + 1))
  else
    verdict=DIFFERENT
  fi
  echo "kill $i at ${at} s: $kept frames in the journal, resumed: $verdict"
done
echo "$same of $n resumed runs byte-identical to the uninterrupted one"
[ "$same" -eq "$n" ]
