#!/usr/bin/env bash
# Set up compass_sparse on a fresh Python machine: the package with its test dependencies.
# SuiteSparse (UMFPACK, AMD, CHOLMOD) and METIS come as binary wheels (kvxopt, pymetis), so
# no system package or compiler is needed.  Safe to run repeatedly; prints what it did.
set -u
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
log() { echo "[setup] $*"; }

PIP="$PY -m pip install -q --root-user-action=ignore"
$PIP --upgrade pip >/dev/null 2>&1 || true
# One install of the package with every extra: dev (test tools), docs (Sphinx, its theme and
# offline MathJax) and plot (matplotlib), so the docs build and the plot tests run inside the
# test suite; the modelling-language links (pyomo: Pyomo + CasADi, gams: GAMSPy) and batch
# (Dask, pyarrow), so their tests run.
if $PIP -e ".[dev,docs,plot,pyomo,gams,batch]"; then
  log "installed compass-sparse with the dev, docs, plot, pyomo, gams and batch extras"
else
  # An optional extra that cannot be installed here must not stop the rest: the package
  # with its test tools first, then each optional extra on its own (its tests skip with a
  # reason when it is absent).
  $PIP -e ".[dev,docs,plot]" || { log "pip install failed"; exit 1; }
  log "installed compass-sparse with the dev, docs and plot extras"
  for extra in pyomo gams batch; do
    if $PIP -e ".[$extra]"; then
      log "installed the $extra extra"
    else
      log "could not install the $extra extra (its tests will skip with a reason)"
    fi
  done
fi
# Check that the package and its SuiteSparse/METIS wheels import.
$PY -c "import compass_sparse, compass_sparse.basis, compass_sparse.basis.ordering, compass_sparse.path._kernels" || exit 1
$PY -c "import kvxopt.umfpack, kvxopt.cholmod, kvxopt.amd, pymetis" || { log "SuiteSparse/METIS wheels not importable"; exit 1; }
# The warm-up: compile the numba kernels now (cached on disk), so that the first solves do
# not spend a minute compiling.  Nothing to do when they are cached already.
log "compiling the solver's kernels (compass-sparse warmup)"
$PY -m compass_sparse.cli warmup || { log "the warm-up failed: solves will compile on first use"; exit 1; }
log "ready"
