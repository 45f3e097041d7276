# Sourced by the cge_0*.sh scripts (from the repository root): the code before a change,
# exported to a scratch directory, and one bench_cge.py part-lu run in a given tree.
root=$(pwd)
base_checkout() {  # BASE -> $tmp holds that revision, with the generators linked in
    tmp=$(mktemp -d)
    git archive "$1" | tar -x -C "$tmp"
    ln -sfn "$root/data/generators" "$tmp/compass_sparse/generators"
}
lu_run() {  # dir suffix args...
    local dir=$1 suffix=$2; shift 2
    (cd "$dir" && PYTHONPATH=. python3 benchmarks/bench_cge.py --parts lu --suffix "$suffix" "$@")
}
