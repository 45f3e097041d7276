#!/usr/bin/env bash
# Section 0c of benchmarks/cge.md: the dynamic CGE counterfactuals with the code before
# (BASE, default ccdc514) and with this checkout, one after the other, each solve in a
# fresh forked process; then the time-limit overruns of this checkout.  Usage (from the
# repository root):
#   bash benchmarks/cge_0c.sh [small|large|limits|all] [BASE]
# small = n = 1e4 and 3e4 (about 8 minutes), large = n = 1e5 capital subsidy (about 5
# minutes), limits = the overrun runs (about 4 minutes).
set -euo pipefail
what=${1:-all}
base=${2:-ccdc514}
source benchmarks/_cge_base.sh
base_checkout "$base"
run() { lu_run "$@" --lu new --families dynamic; }
if [[ $what == small || $what == all ]]; then
    run "$tmp" _dyn_base --sizes 1e4 3e4 --time-limit 300 --splu-max-n 15000
    run "$root" _dyn_new --sizes 1e4 3e4 --time-limit 300 --splu-max-n 15000
    cp "$tmp/benchmarks/results/cge_lu_dyn_base.csv" "$root/benchmarks/results/"
fi
if [[ $what == large || $what == all ]]; then
    run "$tmp" _dyn1e5_base --sizes 1e5 --cases ksub10 --time-limit 400 --splu-max-n 50000
    run "$root" _dyn1e5_new --sizes 1e5 --cases ksub10 --time-limit 400 --splu-max-n 50000
    cp "$tmp/benchmarks/results/cge_lu_dyn1e5_base.csv" "$root/benchmarks/results/"
fi
if [[ $what == limits || $what == all ]]; then
    PYTHONPATH=. python3 benchmarks/bench_cge_time_limit.py --sizes 3e4 1e5 --cases ktax25 \
        --limits 15 60
fi
rm -rf "$tmp"
