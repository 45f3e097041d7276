#!/usr/bin/env bash
# Section 0b of benchmarks/cge.md: the static CGE counterfactuals with the code before the
# factor reuse (BASE, default ccdc514) and with this checkout, one after the other, each
# solve in a fresh forked process.  Usage (from the repository root):
#   bash benchmarks/cge_0b.sh [small|large|all] [BASE]
# small = n = 1e4 and 3e4 (about 6 minutes), large = n = 1e5 (about 15 minutes).
set -euo pipefail
what=${1:-all}
base=${2:-ccdc514}
source benchmarks/_cge_base.sh
base_checkout "$base"
run() { lu_run "$@" --families static --cases tariff25 notax; }
if [[ $what == small || $what == all ]]; then
    run "$root" _r3 --sizes 1e4 3e4 --lu new noreuse --time-limit 200
    run "$tmp" _r3base --sizes 1e4 3e4 --lu new --time-limit 200
    cp "$tmp/benchmarks/results/cge_lu_r3base.csv" benchmarks/results/
fi
if [[ $what == large || $what == all ]]; then
    run "$root" _r3_1e5 --sizes 1e5 --lu new noreuse --time-limit 400 --splu-max-n 200000
    run "$tmp" _r3base_1e5 --sizes 1e5 --lu new --time-limit 400 --splu-max-n 200000
    cp "$tmp/benchmarks/results/cge_lu_r3base_1e5.csv" benchmarks/results/
fi
rm -rf "$tmp"
