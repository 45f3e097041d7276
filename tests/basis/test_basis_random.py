"""Random sequences of column replacements against a dense reference."""

import numpy as np
import pytest
from hypothesis import given, settings, HealthCheck
from hypothesis import strategies as st

from basis_helpers import (check_solves, column_vec, dense_B, dominant_dense_column,
                           dominant_matrix, family_move, family_start, rel_err)
from compass_sparse.basis import (KIND_DENSE, BasisManager, BasisOptions, UpdateStatus)

pytestmark = pytest.mark.usefixtures("lu_choice")

TOL = 1e-9


def run_sequence(n, steps, seed, density=None, options=None, check_every=1):
    rng = np.random.default_rng(seed)
    density = density if density is not None else min(0.3, 4.0 / n)
    M = dominant_matrix(n, density, rng)
    j0 = int(rng.integers(n))
    r = dominant_dense_column(M, j0, rng)
    bm = BasisManager(M, options or BasisOptions())
    bm.set_dense_column(r)
    kinds, indices, signs = family_start(n, rng, r_index=j0 if rng.random() < 0.5 else None)
    rep = bm.factor(kinds, indices, signs)
    assert rep.ok and rep.rank_deficiency == 0
    B = check_solves(bm, M, r, rng, TOL)
    if n <= 600:  # (an SVD of order 2000 alone took seconds on a loaded machine)
        assert np.linalg.cond(B) < 1e6
    statuses = []
    for step in range(steps):
        slot, col = family_move(bm, rng, n, r_index=j0)
        # the entering column, solved with ftran_column (result checked)
        if n <= 200 or step % 10 == 0:
            B = dense_B(bm.kinds, bm.indices, bm.signs, M, r)
            d = bm.ftran_column(*col)
            assert rel_err(d, np.linalg.solve(B, column_vec(*col, M, r))) <= TOL
        st_ = bm.replace(slot, *col)
        statuses.append(st_)
        assert st_ in (UpdateStatus.OK, UpdateStatus.REFACTORED)  # family: never singular
        assert bm.kinds[slot] == col[0] and bm.indices[slot] == col[1]
        if step % check_every == 0 or step == steps - 1:
            B = check_solves(bm, M, r, rng, TOL)
    return bm, statuses


@pytest.mark.parametrize("n,steps,seed,check_every", [
    (5, 150, 1, 1), (12, 150, 2, 1), (40, 200, 3, 1), (150, 200, 4, 1),
    pytest.param(600, 120, 5, 10, marks=pytest.mark.slow)])
def test_random_sequences(n, steps, seed, check_every):
    # n = 600: the dense reference solve every 10th step (each is an O(n^3) LU)
    bm, statuses = run_sequence(n, steps, seed, check_every=check_every)
    assert statuses.count(UpdateStatus.OK) > 0
    assert bm.stats.updates + bm.stats.refactor_by_count + bm.stats.refactor_by_fill \
        + bm.stats.refactor_by_stability >= steps


@pytest.mark.slow
def test_random_sequence_large():
    # n = 2000: dense reference only every 50 steps (each costs a dense LU of order 2000)
    bm, statuses = run_sequence(2000, 100, 11, density=3.0 / 2000, check_every=50)
    assert statuses.count(UpdateStatus.OK) >= 90


@settings(max_examples=12, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(n=st.integers(5, 60), seed=st.integers(0, 2**31 - 1),
       limit=st.sampled_from([0, 1, 3, 50]), fill=st.sampled_from([1.2, 2.0, 10.0]))
def test_random_sequences_property(n, seed, limit, fill):
    opts = BasisOptions(update_limit=limit, fill_factor=fill, residual_check_frequency=3)
    run_sequence(n, 30, seed, options=opts)


def test_dense_column_moves():
    """The dense column enters and leaves repeatedly."""
    rng = np.random.default_rng(7)
    n = 30
    M = dominant_matrix(n, 0.1, rng)
    j0 = 4
    r = dominant_dense_column(M, j0, rng)
    bm = BasisManager(M)
    bm.set_dense_column(r)
    bm.factor(*family_start(n, rng))
    for it in range(40):
        s = bm.slot_of_dense()
        if s >= 0:
            st_ = bm.replace(s, 1, j0, -1.0)
        else:
            s = max(bm.slot_of_m(j0), bm.slot_of_unit(j0))
            bm.ftran_column(KIND_DENSE, 0, 1.0)
            st_ = bm.replace(s, KIND_DENSE, 0, 1.0)
        assert st_ == UpdateStatus.OK
        check_solves(bm, M, r, rng, TOL)
    assert bm.stats.updates == 40
