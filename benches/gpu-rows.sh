#!/bin/bash
# The GPU rows of docs/benchmarks.md: the energy's backends, then `bench track` with the GPU engine
# and the CPU reference, on procedural arches and on the real scans. Each step's output goes to
# OUT/<step>.txt; one that hangs is stopped by its timeout so that the others still run.
#
#   benches/gpu-rows.sh [JAWTRACK] [SCANS] [OUT]
#
# Needs a Vulkan driver for the GPU (JAWTRACK_ADAPTER=name picks one when there are several).
set -u
B=${1:-target/release/jawtrack}
S=${2:-../shared/data/scan-tag0}
O=${3:-bench-gpu}
mkdir -p "$O"
step() {
    local name=$1 limit=$2
    shift 2
    echo "== $name: $*"
    local start=$(date +%s%N)
    timeout "$limit" "$@" >"$O/$name.txt" 2>&1
    echo "   rc=$? $((($(date +%s%N) - start) / 1000000)) ms"
    grep -v XDG_RUNTIME "$O/$name.txt" | tail -n 40
}
step energy 120 "$B" bench energy --seconds 0.5 --scans "$S"
T="$B bench track --no-floor --mouth with"
step gn-gpu 90 $T --frames 34 --seeds 1,2,3 --search gauss-newton --backend gpu
step paper-gpu 100 $T --frames 34 --seeds 1,2,3 --search paper --backend gpu
step gn-cpu 60 $T --frames 34 --seeds 1,2,3 --search gauss-newton --backend cpu
step scan-gn-gpu 60 $T --frames 16 --seeds 1 --search gauss-newton --backend gpu --meshes "$S"
step scan-paper-gpu 70 $T --frames 16 --seeds 1 --search paper --backend gpu --meshes "$S"
step scan-gn-cpu 60 $T --frames 16 --seeds 1 --search gauss-newton --backend cpu --meshes "$S"
