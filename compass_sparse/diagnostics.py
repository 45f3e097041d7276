"""Help for the most common mistake in a model: a Jacobian that is not the derivative of F.

A wrong J (a flipped sign, a missing term, a row for another variable) does not make the
solver fail loudly: the Newton steps simply stop reducing the merit function, and the
solve ends in NO_PROGRESS or STATIONARY_POINT after many restarts.  Two tools:

* :func:`check_jacobian` compares J(x) with central differences of F,

      D[:, j] = (F(x + h_j e_j) - F(x - h_j e_j)) / (2 h_j),   h_j = eps^(1/3) max(1, |x_j|),

  column by column (2 n evaluations of F; a sample of the columns for large n) and names
  the entries that disagree most, by the problem's names;
* :func:`directional_mismatch` is the cheap test a failed solve makes at its end: the
  directional derivative J(z) d against the forward difference (F(z + h d) - F(z)) / h
  along the solve's step d (from its start to the returned point) and along a fixed
  pseudo-random direction -- two evaluations of F.  When they disagree the failed solve's
  message says so and names :func:`check_jacobian`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .problem.mcp import MCP

__all__ = ["JacobianCheck", "check_jacobian", "directional_mismatch"]

MISMATCH = 1e-2
"""Relative disagreement of J d and the difference quotient above which a failed solve's
message names check_jacobian: a correct J disagrees by the difference's truncation and
rounding errors (~1e-7 relative with the step below), a wrong entry that d touches by
O(1)."""


@dataclass
class JacobianCheck:
    """What :func:`check_jacobian` found.  ``worst``: the entries of largest error, as
    (row name, variable name, J's value, the finite difference, error), the error being
    ``|J - D| / max(1, |D|)``; ``max_error`` the largest; ``ok`` whether it is at most the
    tolerance; ``columns`` how many columns were compared (all, or a sample);
    ``skipped`` the columns where F could not be evaluated at x +- h e_j."""

    ok: bool
    max_error: float
    tolerance: float
    worst: list = field(default_factory=list)
    columns: int = 0
    skipped: list = field(default_factory=list)

    def __str__(self):
        head = (f"Jacobian {'agrees' if self.ok else 'DISAGREES'} with finite differences of "
                f"F: largest error {self.max_error:.2e} (tolerance {self.tolerance:.0e}) on "
                f"{self.columns} column(s)")
        lines = [head]
        if self.worst and not self.ok:
            lines.append(f"  {'row':24s} {'variable':24s} {'J':>12s} {'differences':>12s}")
            for r, c, j, d, e in self.worst:
                if e > self.tolerance:
                    lines.append(f"  {r:24s} {c:24s} {j:12.4e} {d:12.4e}")
        if self.skipped:
            lines.append(f"  F failed near x in {len(self.skipped)} column(s), not compared: "
                         + ", ".join(self.skipped[:5]) + (" ..." if len(self.skipped) > 5
                                                          else ""))
        return "\n".join(lines)


def _labels(problem, var_names, eqn_names, n):
    """(row label, column label) callables: the MCP's, or from the names given."""
    if problem is not None:
        return problem.row_label, problem.var_label
    var = (lambda j: str(var_names[j])) if var_names is not None else (lambda j: f"x[{j}]")
    if eqn_names is not None:
        row = lambda i: str(eqn_names[i])
    elif var_names is not None:
        row = lambda i: f"F({var_names[i]})"
    else:
        row = lambda i: f"F[{i}]"
    return row, var


def check_jacobian(F, J=None, x=None, *, var_names=None, eqn_names=None, tol: float = 1e-4,
                   max_columns: int = 1000, seed: int = 0, k_worst: int = 5) -> JacobianCheck:
    """Compare J(x) with central finite differences of F at x and name the worst entries.

    Parameters
    ----------
    F : callable or MCP
        ``F(x) -> (n,)``, or an :class:`~compass_sparse.MCP` (then its J, its start point
        as the default x, and its names are used).
    J : callable
        ``J(x)`` -> a scipy.sparse matrix or a dense array (not needed with an MCP).  With
        ``jac=True`` models, pass ``lambda x: F(x)[1]`` and ``lambda x: F(x)[0]``.
    x : array
        Where to compare: a point inside F's domain, preferably not at a kink (a max or
        an abs), e.g. a start point or a solve's returned point.
    var_names, eqn_names : sequences of str, optional
        Names of the variables and rows in the report.
    tol : float
        An entry is wrong when ``|J - D| > tol * max(1, |D|)``.
    max_columns : int
        Columns compared at most: all of them up to this n, a seeded random sample above.

    Returns
    -------
    JacobianCheck
        ``ok``, ``max_error`` and the ``worst`` entries by name; ``print()`` it.
    """
    problem = F if isinstance(F, MCP) else None
    if problem is not None:
        x = problem.x0 if x is None else x
        f_of = problem.F_uncounted
        j_of = problem.evaluator.J
    else:
        if J is None or x is None:
            raise TypeError("check_jacobian(F, J, x) needs J and x (or an MCP as F)")
        f_of, j_of = F, J
    x = np.array(x, dtype=float).reshape(-1)
    n = x.size
    row, col = _labels(problem, var_names, eqn_names, n)
    Jx = j_of(x.copy())
    Jx = sp.csc_matrix(Jx) if sp.issparse(Jx) else np.asarray(Jx, dtype=float)
    if Jx.shape != (n, n):
        raise ValueError(f"J(x) has shape {Jx.shape}, expected ({n}, {n})")

    def column(j):  # column j of J(x), dense (a sparse J is never made dense whole)
        if isinstance(Jx, np.ndarray):
            return Jx[:, j]
        c = np.zeros(n)
        c[Jx.indices[Jx.indptr[j]:Jx.indptr[j + 1]]] = Jx.data[Jx.indptr[j]:Jx.indptr[j + 1]]
        return c
    cols = np.arange(n)
    if n > max_columns:
        cols = np.sort(np.random.default_rng(seed).choice(n, max_columns, replace=False))
    errs, skipped = [], []
    for j in cols.tolist():
        h = np.finfo(float).eps ** (1 / 3) * max(1.0, abs(x[j]))
        xp, xm = x.copy(), x.copy()
        xp[j] += h
        xm[j] -= h
        with np.errstate(all="ignore"):
            try:
                d = (np.asarray(f_of(xp), float).reshape(-1)
                     - np.asarray(f_of(xm), float).reshape(-1)) / (xp[j] - xm[j])
            except Exception:
                d = None
        if d is None or not np.all(np.isfinite(d)):
            skipped.append(col(j))
            continue
        cj = column(j)
        e = np.abs(cj - d) / np.maximum(1.0, np.abs(d))
        for i in np.argsort(-e, kind="stable")[:k_worst].tolist():
            errs.append((float(e[i]), i, j, float(cj[i]), float(d[i])))
    errs.sort(key=lambda t: -t[0])
    worst = [(row(i), col(j), jv, dv, e) for e, i, j, jv, dv in errs[:k_worst]]
    max_error = errs[0][0] if errs else 0.0
    return JacobianCheck(ok=max_error <= tol, max_error=max_error, tolerance=tol,
                         worst=worst, columns=int(cols.size) - len(skipped), skipped=skipped)


def directional_mismatch(problem, z, start) -> float:
    """The largest relative disagreement between J(z) d and (F(z + h d) - F(z)) / h over
    two directions d: the step from ``start`` to z and a fixed pseudo-random one; 0.0
    when F cannot be evaluated there (nothing is concluded).  Evaluates F twice and J
    once, outside the solve's counts."""
    if problem.evaluator.jac_mode is None:
        return 0.0  # J is F's own differences: nothing to compare
    z = np.asarray(z, dtype=float)
    n = z.size
    dirs = []
    step = z - np.asarray(start, dtype=float)
    if np.any(step != 0) and np.all(np.isfinite(step)):
        dirs.append(step)
    dirs.append(np.random.default_rng(12345).choice([-1.0, 1.0], n))
    saved = (problem.counters.nfev, problem.counters.njev)
    try:
        with np.errstate(all="ignore"):
            f0 = problem.F_uncounted(z)
            Jz = problem.evaluator.J(z)
            worst = 0.0
            for d in dirs:
                scale = max(1.0, float(np.max(np.abs(z))))
                h = np.sqrt(np.finfo(float).eps) * scale / float(np.max(np.abs(d)))
                fd = (problem.F_uncounted(z + h * d) - f0) / h
                jd = Jz @ d
                if not (np.all(np.isfinite(fd)) and np.all(np.isfinite(jd))):
                    continue
                size = max(float(np.max(np.abs(fd))), float(np.max(np.abs(jd))), 1e-12)
                worst = max(worst, float(np.max(np.abs(jd - fd))) / size)
            return worst
    except Exception:
        return 0.0
    finally:
        problem.counters.nfev, problem.counters.njev = saved
