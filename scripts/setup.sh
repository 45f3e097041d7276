#!/usr/bin/env bash
# Set up compass_sparse on a fresh Debian/Python machine: the system library for the
# optional SuiteSparse extra (when we are root and apt works), then the package with its
# test dependencies.  Safe to run repeatedly; prints what it did.
set -u
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
log() { echo "[setup] $*"; }

have_suitesparse_headers() { [ -f /usr/include/suitesparse/cholmod.h ]; }

if ! have_suitesparse_headers; then
  if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then
    log "installing libsuitesparse-dev (for the optional CHOLMOD extra)"
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libsuitesparse-dev) \
      >/tmp/compass_sparse_apt.log 2>&1 || log "apt-get failed; continuing without SuiteSparse (see /tmp/compass_sparse_apt.log)"
  else
    log "not root or no apt-get: continuing without SuiteSparse"
  fi
fi

$PY -m pip install -q --upgrade pip >/dev/null 2>&1 || true
# dev: the test tools; docs + plot: Sphinx and matplotlib, so the docs build and the
# plot tests run inside the test suite.
if have_suitesparse_headers && $PY -m pip install -q -e ".[dev,docs,plot,suitesparse]"; then
  log "installed compass-sparse with the dev, docs, plot and suitesparse extras"
else
  log "installing without the suitesparse extra (its tests will skip with a reason)"
  $PY -m pip install -q -e ".[dev,docs,plot]" || { log "pip install failed"; exit 1; }
fi
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
# Compile the numba kernels once so the first solve is not slowed by compilation.
$PY -c "import compass_sparse, compass_sparse.basis, compass_sparse._path_kernels" || exit 1
log "ready"
