"""Merit functions and residuals of MCP(F, [l, u]).

Fischer–Burmeister (thesis §2.6, after Billups): with phi(a, b) = sqrt(a^2 + b^2) - a - b,
which vanishes exactly when a >= 0, b >= 0, ab = 0, define row-wise

    lower bound only   Phi_i = phi(z_i - l_i, F_i)
    upper bound only   Phi_i = -phi(u_i - z_i, -F_i)
    both bounds        Phi_i = phi(z_i - l_i, phi(u_i - z_i, -F_i))
    free               Phi_i = -F_i

so Phi(z) = 0 iff z solves the MCP.  The merit function is Psi = 0.5 ||Phi||^2, which is
continuously differentiable; ||Phi||_2 is PATH's convergence measure.

An element H of the generalized Jacobian of Phi has the form H = Da + Db J(z) with
diagonal Da, Db (computed by :func:`fb_jacobian_diagonals`), so grad Psi = H^T Phi
= Da Phi + J^T (Db Phi).  At a kink (a = b = 0) we take the derivative of the smooth branch
along the diagonal direction (a, b) = (1, 1)/sqrt(2), a valid element of the generalized
gradient; Psi's gradient does not depend on that choice because Phi vanishes there.

The normal map (thesis §3.1) is F_B(x) = F(pi(x)) + x - pi(x) with pi the projection on
the box; x solves F_B(x) = 0 iff z = pi(x) solves the MCP.  The natural (minimum-map)
residual ||z - pi(z - F(z))||_inf is the independent check applied to every returned
point.

The box's own toolkit (the projection pi, the norms, the float-vector tests) is
:mod:`compass_sparse.box`.

phi is evaluated in the cancellation-free form -2ab / (sqrt(a^2+b^2) + a + b) when
a + b > 0, so that Phi keeps full relative accuracy near a solution with a, b > 0.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .linalg._csc_kernels import csc_rmatvec
from ._merit_kernels import (fb_diagonals_kernel, fb_directional_kernel, fb_gradient_kernel,
                             fb_phi_kernel, normal_map_kernel, residual_report_kernel)
from .box import broadcast_box, float_vector, max_abs, norm2, project, solver_vectors

__all__ = [
    "fischer",
    "fb_phi",
    "fb_psi",
    "fb_jacobian_diagonals",
    "fb_gradient",
    "fb_directional",
    "normal_map",
    "normal_map_at",
    "natural_residual",
    "min_map",
    "ResidualReport",
    "residual_report",
]


def fischer(a, b):
    """phi(a, b) = sqrt(a^2 + b^2) - a - b, elementwise, without cancellation.

    The arguments are scaled by a power of two (exact) so that neither a + b nor a * b
    overflows or underflows for huge or tiny |a|, |b|."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    big = np.maximum(np.abs(a), np.abs(b))
    e = np.frexp(np.where(np.isfinite(big), big, 1.0))[1]
    a = np.ldexp(a, -e)
    b = np.ldexp(b, -e)
    r = np.hypot(a, b)
    s = a + b
    with np.errstate(invalid="ignore", divide="ignore"):
        stable = -2.0 * (a / (r + s)) * b
    out = np.where(s > 0, np.where(r + s > 0, stable, 0.0), r - s)
    return np.ldexp(out, e)


def _fischer_grad(a, b):
    """(d phi / da, d phi / db), using the direction (1, 1)/sqrt(2) at (0, 0)."""
    r = np.hypot(a, b)
    zero = r == 0
    rs = np.where(zero, 1.0, r)
    ga = np.where(zero, 1.0 / np.sqrt(2.0), a / rs) - 1.0
    gb = np.where(zero, 1.0 / np.sqrt(2.0), b / rs) - 1.0
    return ga, gb










def _kinds(lb, ub):
    fl = np.isfinite(lb)
    fu = np.isfinite(ub)
    return fl & ~fu, ~fl & fu, fl & fu, ~fl & ~fu


def fb_phi(z, f, lb, ub):
    """The Fischer–Burmeister vector Phi(z) for given F values f = F(z)."""
    if solver_vectors(z, f, lb, ub):
        # the solver's own vectors (every evaluated point): straight to the kernel
        phi = np.empty(z.shape[0])
        fb_phi_kernel(z, f, lb, ub, phi)
        return phi
    z = np.asarray(z, dtype=float)
    f = np.asarray(f, dtype=float)
    lb, ub = broadcast_box(lb, ub, z)
    if z.ndim == 1 and f.shape == z.shape:
        phi = np.empty_like(z)
        fb_phi_kernel(np.ascontiguousarray(z), np.ascontiguousarray(f),
                      np.ascontiguousarray(lb), np.ascontiguousarray(ub), phi)
        return phi
    return fb_phi_arrays(z, f, lb, ub)


def fb_phi_arrays(z, f, lb, ub):
    """fb_phi with array operations (the reference of the compiled kernel)."""
    z = np.asarray(z, dtype=float)
    f = np.asarray(f, dtype=float)
    lb, ub = broadcast_box(lb, ub, z)
    lo, up, box, free = _kinds(lb, ub)
    phi = np.empty_like(z)
    if lo.any():
        phi[lo] = fischer(z[lo] - lb[lo], f[lo])
    if up.any():
        phi[up] = -fischer(ub[up] - z[up], -f[up])
    if box.any():
        inner = fischer(ub[box] - z[box], -f[box])
        phi[box] = fischer(z[box] - lb[box], inner)
    phi[free] = -f[free]
    return phi


def fb_psi(phi) -> float:
    """Psi = 0.5 ||Phi||^2.  (The array's own dot method: the same BLAS product as np.dot
    without the function's dispatch, a third of its cost on a short vector; asked at
    every evaluated point.)"""
    if phi.__class__ is np.ndarray:
        return 0.5 * float(phi.dot(phi))
    return 0.5 * float(np.dot(phi, phi))


def fb_jacobian_diagonals(z, f, lb, ub):
    """Diagonals (da, db) with H = diag(da) + diag(db) J an element of d Phi(z)."""
    z = np.asarray(z, dtype=float)
    f = np.asarray(f, dtype=float)
    lb, ub = broadcast_box(lb, ub, z)
    if z.ndim == 1 and f.shape == z.shape:
        da = np.empty_like(z)
        db = np.empty_like(z)
        fb_diagonals_kernel(np.ascontiguousarray(z), np.ascontiguousarray(f),
                            np.ascontiguousarray(lb), np.ascontiguousarray(ub), da, db)
        return da, db
    return fb_jacobian_diagonals_arrays(z, f, lb, ub)


def fb_jacobian_diagonals_arrays(z, f, lb, ub):
    """fb_jacobian_diagonals with array operations (the reference of the compiled kernel)."""
    z = np.asarray(z, dtype=float)
    f = np.asarray(f, dtype=float)
    lb, ub = broadcast_box(lb, ub, z)
    lo, up, box, free = _kinds(lb, ub)
    da = np.zeros_like(z)
    db = np.zeros_like(z)
    if lo.any():
        da[lo], db[lo] = _fischer_grad(z[lo] - lb[lo], f[lo])
    if up.any():
        # Phi = -phi(u - z, -F): d/dz = phi_a, d/dF = phi_b
        da[up], db[up] = _fischer_grad(ub[up] - z[up], -f[up])
    if box.any():
        a1 = ub[box] - z[box]
        c = fischer(a1, -f[box])
        ia, ib = _fischer_grad(a1, -f[box])  # of c = phi(u - z, -F)
        oa, ob = _fischer_grad(z[box] - lb[box], c)  # of phi(z - l, c)
        da[box] = oa - ob * ia
        db[box] = -ob * ib
    db[free] = -1.0
    return da, db






def _kernel_gradient_args(z, J, phi) -> bool:
    """Whether Phi and J are what the compiled gradient takes, beside the solver's float
    vectors z, f, l, u: Phi a float vector like z, J a square float64 CSC matrix."""
    return (float_vector(phi) and phi.shape == z.shape and sp.issparse(J)
            and J.format == "csc" and J.shape == (z.shape[0],) * 2
            and J.data.dtype == np.float64)


def fb_gradient(z, f, J, lb, ub, phi=None):
    """grad Psi(z) = H^T Phi with H = diag(da) + diag(db) J."""
    if phi is None:
        phi = fb_phi(z, f, lb, ub)
    vectors = solver_vectors(z, f, lb, ub)
    if vectors and _kernel_gradient_args(z, J, phi):
        # the solver's own vectors and J (the descent test of every major iteration)
        g = np.empty(z.shape[0])
        fb_gradient_kernel(z, f, lb, ub, phi, J.indptr, J.indices, J.data, g)
        return g
    if vectors:
        da = np.empty(z.shape[0])
        db = np.empty(z.shape[0])
        fb_diagonals_kernel(z, f, lb, ub, da, db)
    else:
        da, db = fb_jacobian_diagonals(z, f, lb, ub)
    u = db * phi
    if sp.issparse(J) and J.format == "csc":
        jtu = np.empty(J.shape[1])
        csc_rmatvec(J.indptr, J.indices, J.data, u, jtu)  # J^T u without building J^T
        return da * phi + jtu
    return da * phi + J.T @ u


def fb_directional(z, f, J, lb, ub, phi, zc) -> float:
    """grad Psi(z) . (zc - z): the directional derivative of the merit function towards
    zc, as ``fb_gradient(z, f, J, lb, ub, phi) @ (zc - z)`` (the same bits), in one
    compiled call for the solver's own vectors and J (the descent test of a major
    iteration: the gradient, the difference and the product were three calls and three
    arrays)."""
    if (solver_vectors(z, f, lb, ub) and _kernel_gradient_args(z, J, phi)
            and float_vector(zc) and zc.shape == z.shape):
        w = np.empty((2, z.shape[0]))  # g and zc - z: one allocation, C rows
        return float(fb_directional_kernel(z, f, lb, ub, phi, J.indptr, J.indices, J.data,
                                           zc, w[0], w[1]))
    return float(fb_gradient(z, f, J, lb, ub, phi) @ (np.asarray(zc, dtype=float) - z))




def normal_map(x, f_at_pi, lb, ub):
    """F_B(x) = F(pi(x)) + x - pi(x), given f_at_pi = F(pi(x))."""
    return f_at_pi + x - project(x, lb, ub)


def min_map(z, f, lb, ub):
    """z - pi(z - F(z)): zero exactly at solutions.

    Evaluated as the median of (z - u, F, z - l), which equals z - pi(z - F) but never
    forms z - F: a small F next to a large z is not absorbed by rounding."""
    z = np.asarray(z, dtype=float)
    f = np.asarray(f, dtype=float)
    if np.isfinite(z).all():  # the solver's points: no inf - inf, no errstate to pay for
        return np.minimum(np.maximum(f, z - ub), z - lb)
    with np.errstate(invalid="ignore"):
        return np.minimum(np.maximum(f, z - ub), z - lb)


def natural_residual(z, f, lb, ub) -> float:
    """||z - pi(z - F(z))||_inf, the natural (minimum-map) residual."""
    return max_abs(min_map(z, f, lb, ub))


@dataclass
class ResidualReport:
    """Accuracy measures of a point z (thesis §2.6; PATH's final statistics).

    ``fb_norm`` (||Phi||_2) is the convergence measure; ``natural`` is the independent check.
    ``worst`` lists (row name, |Phi_i|, |min-map_i|) for the rows with the largest |Phi_i|.
    """

    fb_norm: float
    fb_inf: float
    natural: float
    normal_map_inf: float
    merit: float
    worst: list = field(default_factory=list)
    worst_index: int = -1

    def summary(self) -> str:
        w = f", worst row {self.worst[0][0]}" if self.worst else ""
        return (
            f"||Phi||_2 = {self.fb_norm:.3e}, ||Phi||_inf = {self.fb_inf:.3e}, "
            f"natural residual = {self.natural:.3e}{w}"
        )


def residual_report(z, f, lb, ub, *, names=None, k_worst: int = 5,
                    phi=None) -> ResidualReport:
    """All residual measures at z with F values f, naming the k worst rows.

    ``names`` is a callable i -> str or a sequence of row names; ``phi`` is
    fb_phi(z, f, lb, ub) when the caller has it.
    """
    z = np.asarray(z, dtype=float)
    f = np.asarray(f, dtype=float)
    lb, ub = broadcast_box(lb, ub, z)
    if phi is None:
        phi = fb_phi(z, f, lb, ub)
    aphi = None  # |Phi|, made only where a sort needs it
    k = min(k_worst, z.size)
    idx = np.empty(k, dtype=np.int64)
    distinct = False  # whether idx holds the k largest |Phi_i| (unique: no ties)
    if z.ndim == 1 and f.shape == z.shape and float_vector(phi):
        mm = np.empty_like(z)
        fb_inf, natural, nm_inf, fb_norm, sq, distinct = residual_report_kernel(
            np.ascontiguousarray(z), np.ascontiguousarray(f), np.ascontiguousarray(lb),
            np.ascontiguousarray(ub), np.ascontiguousarray(phi), mm, idx)
        psi = 0.5 * sq  # (fb_psi's formula)
    else:
        aphi = np.abs(phi)
        mm = np.abs(min_map(z, f, lb, ub))
        nm = normal_map_at_arrays(z, f, lb, ub)[1]
        fb_inf, natural, nm_inf = (float(np.max(aphi)), float(np.max(mm)),
                                   float(np.max(np.abs(nm)))) if z.size else (0.0, 0.0, 0.0)
        fb_norm, psi = norm2(phi, fb_inf), fb_psi(phi)
    # the k largest came from one compiled pass when they are distinct (then the answer
    # is unique: the sorts below give it too); ties keep numpy's order
    if not distinct:
        aphi = np.abs(phi) if aphi is None else aphi
        if k == z.size:
            # every row is listed (small problems): one sort, no partition first
            idx = np.argsort(-aphi, kind="stable")  # ties: the lower row first
        else:
            idx = np.argpartition(-aphi, k - 1)[:k] if k > 0 else np.array([], dtype=int)
            idx = idx[np.argsort(-aphi[idx])]
    if names is None:
        label = lambda i: f"F[{i}]"  # noqa: E731
    elif callable(names):
        label = names
    else:
        label = lambda i: str(names[i])  # noqa: E731
    worst = [(label(i), abs(float(phi[i])), float(mm[i])) for i in idx.tolist()]
    return ResidualReport(
        fb_norm=float(fb_norm),
        fb_inf=float(fb_inf),
        natural=float(natural),
        normal_map_inf=float(nm_inf),
        merit=float(psi),
        worst=worst,
        worst_index=int(idx[0]) if k > 0 else -1,
    )






def normal_map_at(z, f, lb, ub):
    """(x, F_B(x)) for the x with pi(x) = z that minimizes ||F_B(x)|| componentwise:
    F_B(x) is F minus the part of F that the normal cone of the box at z absorbs (thesis
    (2.5.8)-(2.5.9)): at a lower bound x_i = z_i - max(F_i, 0), at an upper bound
    x_i = z_i + max(-F_i, 0), a fixed variable absorbs all of F_i."""
    if (isinstance(z, np.ndarray) and isinstance(f, np.ndarray) and z.ndim == 1
            and f.shape == z.shape and z.dtype == float and f.dtype == float):
        lb, ub = broadcast_box(lb, ub, z)
        x = np.empty_like(z)
        nm = np.empty_like(z)
        normal_map_kernel(z, f, lb, ub, x, nm)
        return x, nm
    return normal_map_at_arrays(z, f, lb, ub)


def normal_map_at_arrays(z, f, lb, ub):
    """normal_map_at with array operations (the reference of the compiled kernel)."""
    at_l = z <= lb
    at_u = (z >= ub) & ~at_l
    w = np.where(at_l, np.maximum(f, 0.0), 0.0)  # absorbed at the lower bound
    v = np.where(at_u, np.maximum(-f, 0.0), 0.0)
    fixed = lb == ub
    w = np.where(fixed, np.maximum(f, 0.0), w)
    v = np.where(fixed, np.maximum(-f, 0.0), v)
    x = z - w + v
    return x, f - w + v
