#!/usr/bin/env bash
# Section 0b of benchmarks/cge.md: the static CGE counterfactuals with the code before the
# factor reuse (BASE, default ccdc514) and with this checkout, one after the other, each
# solve in a fresh forked process.  Usage (from the repository root):
#   bash benchmarks/cge_0b.sh [small|large|all] [BASE]
# small = n = 1e4 and 3e4 (about 6 minutes), large = n = 1e5 (about 15 minutes).
set -euo pipefail
what=${1:-all}
base=${2:-ccdc514}
root=$(pwd)
tmp=$(mktemp -d)
git archive "$base" | tar -x -C "$tmp"
ln -sfn "$root/data/generators" "$tmp/compass_sparse/generators"
run() {  # dir suffix args...
    local dir=$1 suffix=$2; shift 2
    (cd "$dir" && PYTHONPATH=. python3 benchmarks/bench_cge.py --parts lu --families static \
        --cases tariff25 notax --suffix "$suffix" "$@")
}
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
