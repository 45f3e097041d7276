#!/usr/bin/env bash
# Set up compass_sparse on a fresh Python machine: the package with its test dependencies.
# SuiteSparse (UMFPACK, AMD, CHOLMOD) and METIS come as binary wheels (kvxopt, pymetis), so
# no system package or compiler is needed.  Safe to run repeatedly; prints what it did.
set -u
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
log() { echo "[setup] $*"; }

$PY -m pip install -q --upgrade pip >/dev/null 2>&1 || true
$PY -m pip install -q -e ".[dev]" || { log "pip install failed"; exit 1; }
log "installed compass-sparse with the dev extra"
# Compile the numba kernels once so the first solve is not slowed by compilation.
$PY -c "import compass_sparse, compass_sparse.basis, compass_sparse.basis.ordering, compass_sparse._path_kernels" || exit 1
$PY -c "import kvxopt.umfpack, kvxopt.cholmod, kvxopt.amd, pymetis" || { log "SuiteSparse/METIS wheels not importable"; exit 1; }
log "ready"
