#!/usr/bin/env bash
# Set up compass_sparse on a fresh Python machine: the package with its test dependencies.
# SuiteSparse (UMFPACK, AMD, CHOLMOD) and METIS come as binary wheels (kvxopt, pymetis), so
# no system package or compiler is needed.  Safe to run repeatedly; prints what it did.
set -u
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
log() { echo "[setup] $*"; }

$PY -m pip install -q --upgrade pip >/dev/null 2>&1 || true
# dev: the test tools; docs + plot: Sphinx and matplotlib, so the docs build and the
# plot tests run inside the test suite.
$PY -m pip install -q -e ".[dev,docs,plot]" || { log "pip install failed"; exit 1; }
log "installed compass-sparse with the dev, docs and plot extras"
# The modelling-language links (Pyomo + CasADi, GAMSPy) are optional extras; CI installs
# them so their tests run.
if $PY -m pip install -q -e ".[pyomo,gams]"; then
  log "installed the pyomo and gams extras"
else
  log "could not install the pyomo/gams extras (their tests will skip with a reason)"
fi
# Scenario batches on Dask with Parquet results (the batch extra); CI installs it so the
# batch tests run.
if $PY -m pip install -q -e ".[batch]"; then
  log "installed the batch extra (dask[distributed], pyarrow)"
else
  log "could not install the batch extra (the Dask and Parquet tests will skip with a reason)"
fi
# Check that the package and its SuiteSparse/METIS wheels import (numba kernels compile on
# first use and are cached on disk).
$PY -c "import compass_sparse, compass_sparse.basis, compass_sparse.basis.ordering, compass_sparse.path._kernels" || exit 1
$PY -c "import kvxopt.umfpack, kvxopt.cholmod, kvxopt.amd, pymetis" || { log "SuiteSparse/METIS wheels not importable"; exit 1; }
log "ready"
