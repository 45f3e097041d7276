"""The package's one dense LU solve in compiled code: numpy's ``linalg.solve`` as numba
compiles it, LAPACK's gesv (getrf followed by getrs on scipy's library), so the bits of
scipy's lu_factor + lu_solve.  Its singular-matrix error is raised exactly when getrf
reports a zero pivot (info > 0).  Used by the crash's reduced systems and by the LU
backends' dense solve (:func:`compass_sparse.basis.backends.solve_sparse`)."""
import numpy as np

from .._jit import njit


@njit(cache=True)
def dense_solve_or_none(A, b):
    """(x, True) with A x = b, or (b, False) when LAPACK finds A exactly singular."""
    try:
        return np.linalg.solve(A, b), True
    except Exception:  # numba's LinAlgError: getrf's info > 0, a zero pivot
        return b, False
