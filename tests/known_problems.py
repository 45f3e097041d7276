"""Small complementarity problems with known solutions, written from their published formulas.

Each problem is a :class:`KnownProblem` holding F, an analytic Jacobian (a dense numpy array,
whose pattern is the full matrix, or a scipy.sparse CSC matrix built from FIXED index arrays
so that explicit zeros stay stored), the bounds, the customary start point and the known
solutions.  Nothing here imports the solver: the tests use these as independent references.

Sources
-------
* Kojima–Shindo (MCPLIB ``kojshin``): Kojima & Shindo (1986); the NCP as given by Harker &
  Pang (1990) and in Dirkse & Ferris, "MCPLIB: a collection of nonlinear mixed
  complementarity problems" (1995).  Two solutions: (1, 0, 3, 0) (non-degenerate) and
  (sqrt(6)/2, 0, 0, 1/2) (degenerate: F_3 = 0 with x_3 = 0).
* Josephy (MCPLIB ``josephy``): Josephy (1979); the Kojima–Shindo data with another third
  row (constant -1, coefficient 3 on x_4); unique solution (sqrt(6)/2, 0, 0, 1/2).
* Mathiesen (Mathiesen 1987), in the NCP form used by Kanzow (1994) and Billups (1995):
  F = (-x2 + x3 + x4, x1 - (4.5 x3 + 2.7 x4)/(x2 + 1), 5 - x1 - (0.5 x3 + 0.3 x4)/(x3 + 1),
  3 - x1); solution set {(lam, 0, 0, 0) : 0 <= lam <= 3}.
* Nash–Cournot duopoly with linear inverse demand p(Q) = a - b Q and constant marginal
  costs c_i: F_i(q) = c_i - p(Q) - q_i p'(Q); equilibrium q_i = (a - 2 c_i + c_j)/(3b).
* Nash–Cournot oligopoly of Murphy, Sherali & Soyster (1982) (MCPLIB ``nash``, 5 firms):
  p(Q) = 5000^(1/gamma) Q^(-1/gamma), gamma = 1.1, costs
  C_i(q) = c_i q + beta_i/(beta_i + 1) L_i^(1/beta_i) q^((beta_i + 1)/beta_i), L_i = 5
  (marginal cost c_i + (L_i q)^(1/beta_i));
  published equilibrium q = (15.4293, 12.4986, 9.6635, 7.1651, 5.1326) (4 decimals).
* A separable box-constrained VI, F_i(x) = x_i^3 - c_i on [l_i, u_i]: solution
  x_i = clip(cbrt(c_i), l_i, u_i) (strictly monotone, unique).
* Degenerate root: F(x) = x^2 - 2x + 1 = (x - 1)^2 with x free: solution 1, a double root
  (J(1) = 0), where Newton converges only linearly.
* billups (Billups 1995, MCPLIB ``billups``): F(x) = (x - 1)^2 - 1.01, x >= 0; unique
  solution 1 + sqrt(1.01).  From x0 = 0 the merit function has a local minimizer near
  x = 1 that is not a solution; PATH fails from there.
* Domain-restricted problems: F_i(x) = log(x_i) - c_i on x >= 0 (undefined at x_i = 0, where
  a Newton step from the start lands after projection); solution x_i = exp(c_i).  And
  F(x) = sqrt(x - 1) + x - 3 on x >= 0 (undefined for x < 1): solution x = 2.

The homotopy's tests also share two problems given as (F, J, lb, ub, x0) tuples:
:func:`stationary_quadratic`, whose merit function has a stationary point on the box that
is not a solution, and :func:`diverging_free`, whose zero curves diverge.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import scipy.sparse as sp


@dataclass
class KnownProblem:
    name: str
    F: Callable
    J: Callable
    lb: np.ndarray
    ub: np.ndarray
    x0: np.ndarray
    solutions: list = field(default_factory=list)  # known isolated solutions
    solution_set: Callable | None = None  # distance of x to a known solution continuum
    source: str = ""

    @property
    def n(self) -> int:
        return self.x0.size

    def distance_to_solutions(self, x) -> float:
        """Distance (inf-norm) of x to the nearest known solution."""
        d = [float(np.max(np.abs(np.asarray(x) - s))) for s in self.solutions]
        if self.solution_set is not None:
            d.append(float(self.solution_set(np.asarray(x))))
        return min(d) if d else np.inf


# ----------------------------------------------------------------------------- Kojima–Shindo
def _kojshin_F(x, third_row):
    x1, x2, x3, x4 = x
    return np.array([
        3 * x1**2 + 2 * x1 * x2 + 2 * x2**2 + x3 + 3 * x4 - 6,
        2 * x1**2 + x1 + x2**2 + 3 * x3 + 2 * x4 - 2,
        third_row(x1, x2, x3, x4),
        x1**2 + 3 * x2**2 + 2 * x3 + 3 * x4 - 3,
    ])


def _kojshin_J(x, third_grad):
    x1, x2, x3, x4 = x
    return np.array([
        [6 * x1 + 2 * x2, 2 * x1 + 4 * x2, 1.0, 3.0],
        [4 * x1 + 1, 2 * x2, 3.0, 2.0],
        third_grad(x1, x2, x3, x4),
        [2 * x1, 6 * x2, 2.0, 3.0],
    ])


def kojima_shindo(x0=None) -> KnownProblem:
    def row3(x1, x2, x3, x4):
        return 3 * x1**2 + x1 * x2 + 2 * x2**2 + 2 * x3 + 9 * x4 - 9

    def grad3(x1, x2, x3, x4):
        return [6 * x1 + x2, x1 + 4 * x2, 2.0, 9.0]

    return KnownProblem(
        name="kojshin",
        F=lambda x: _kojshin_F(x, row3),
        J=lambda x: _kojshin_J(x, grad3),
        lb=np.zeros(4), ub=np.full(4, np.inf),
        x0=np.zeros(4) if x0 is None else np.asarray(x0, float),
        solutions=[np.array([1.0, 0.0, 3.0, 0.0]),
                   np.array([math.sqrt(6.0) / 2.0, 0.0, 0.0, 0.5])],
        source="Kojima & Shindo (1986); MCPLIB kojshin",
    )


def josephy(x0=None) -> KnownProblem:
    def row3(x1, x2, x3, x4):
        return 3 * x1**2 + x1 * x2 + 2 * x2**2 + 2 * x3 + 3 * x4 - 1

    def grad3(x1, x2, x3, x4):
        return [6 * x1 + x2, x1 + 4 * x2, 2.0, 3.0]

    return KnownProblem(
        name="josephy",
        F=lambda x: _kojshin_F(x, row3),
        J=lambda x: _kojshin_J(x, grad3),
        lb=np.zeros(4), ub=np.full(4, np.inf),
        x0=np.zeros(4) if x0 is None else np.asarray(x0, float),
        solutions=[np.array([math.sqrt(6.0) / 2.0, 0.0, 0.0, 0.5])],
        source="Josephy (1979); MCPLIB josephy",
    )


# ----------------------------------------------------------------------------- Mathiesen
def mathiesen(x0=None) -> KnownProblem:
    def F(x):
        x1, x2, x3, x4 = x
        return np.array([
            -x2 + x3 + x4,
            x1 - (4.5 * x3 + 2.7 * x4) / (x2 + 1.0),
            5.0 - x1 - (0.5 * x3 + 0.3 * x4) / (x3 + 1.0),
            3.0 - x1,
        ])

    def J(x):
        x1, x2, x3, x4 = x
        a = 4.5 * x3 + 2.7 * x4
        b = 0.5 * x3 + 0.3 * x4
        return np.array([
            [0.0, -1.0, 1.0, 1.0],
            [1.0, a / (x2 + 1.0) ** 2, -4.5 / (x2 + 1.0), -2.7 / (x2 + 1.0)],
            [-1.0, 0.0, -(0.5 * (x3 + 1.0) - b) / (x3 + 1.0) ** 2, -0.3 / (x3 + 1.0)],
            [-1.0, 0.0, 0.0, 0.0],
        ])

    def dist(x):
        lam = min(max(x[0], 0.0), 3.0)
        return float(np.max(np.abs(x - np.array([lam, 0.0, 0.0, 0.0]))))

    return KnownProblem(
        name="mathiesen", F=F, J=J, lb=np.zeros(4), ub=np.full(4, np.inf),
        x0=np.ones(4) if x0 is None else np.asarray(x0, float),
        solution_set=dist,
        source="Mathiesen (1987); NCP form of Kanzow (1994)",
    )


# ----------------------------------------------------------------------------- Nash–Cournot
def cournot_duopoly(x0=None, a=10.0, b=1.0, c=(1.0, 2.0)) -> KnownProblem:
    c = np.asarray(c, dtype=float)

    def F(q):
        Q = q.sum()
        return c - (a - b * Q) + b * q

    def J(q):
        return np.array([[2 * b, b], [b, 2 * b]])

    q1 = (a - 2 * c[0] + c[1]) / (3 * b)
    q2 = (a - 2 * c[1] + c[0]) / (3 * b)
    return KnownProblem(
        name="cournot2", F=F, J=J, lb=np.zeros(2), ub=np.full(2, np.inf),
        x0=np.zeros(2) if x0 is None else np.asarray(x0, float),
        solutions=[np.array([q1, q2])], source="linear Cournot duopoly (closed form)",
    )


MSS_C = np.array([10.0, 8.0, 6.0, 4.0, 2.0])
MSS_BETA = np.array([1.2, 1.1, 1.0, 0.9, 0.8])
MSS_L = np.full(5, 5.0)
MSS_GAMMA = 1.1
MSS_SOLUTION = np.array([15.4293, 12.4986, 9.6635, 7.1651, 5.1326])


def nash_cournot_mss(x0=None) -> KnownProblem:
    """Murphy–Sherali–Soyster 5-firm oligopoly (MCPLIB nash).  F is undefined for q_i < 0
    with non-integer exponents and at Q = 0 (returns NaN/Inf there)."""
    c, beta, L, g = MSS_C, MSS_BETA, MSS_L, MSS_GAMMA
    k = 5000.0 ** (1.0 / g)

    def F(q):
        Q = q.sum()
        with np.errstate(all="ignore"):
            p = k * Q ** (-1.0 / g)
            dp = -(1.0 / g) * p / Q
            mc = c + (L * q) ** (1.0 / beta)
        return mc - p - q * dp

    def J(q):
        Q = q.sum()
        with np.errstate(all="ignore"):
            p = k * Q ** (-1.0 / g)
            dp = -(1.0 / g) * p / Q
            d2p = (1.0 / g) * (1.0 / g + 1.0) * p / Q**2
            dmc = (1.0 / beta) * L ** (1.0 / beta) * q ** (1.0 / beta - 1.0)
        # dF_i/dq_j = delta_ij dmc_i - dp - delta_ij dp - q_i d2p
        Jm = np.empty((5, 5))
        Jm[:] = -dp
        Jm -= q[:, None] * d2p
        Jm[np.diag_indices(5)] += dmc - dp
        return Jm

    return KnownProblem(
        name="nash5", F=F, J=J, lb=np.zeros(5), ub=np.full(5, np.inf),
        x0=np.full(5, 10.0) if x0 is None else np.asarray(x0, float),
        solutions=[MSS_SOLUTION.copy()],
        source="Murphy, Sherali & Soyster (1982); MCPLIB nash",
    )


# ----------------------------------------------------------------------------- box VI
def separable_box_vi(x0=None) -> KnownProblem:
    """F_i = x_i^3 - c_i on boxes chosen so that the solution has interior components and
    components at either bound.  The Jacobian is a CSC diagonal with a fixed pattern."""
    c = np.array([8.0, -1.0, 27.0, 0.125, -8.0, 1.0])
    lb = np.array([0.0, 0.0, -1.0, -1.0, -3.0, 2.0])
    ub = np.array([3.0, 1.0, 2.0, 1.0, 3.0, 4.0])
    sol = np.clip(np.cbrt(c), lb, ub)  # (2, 0, 2, 0.5, -2, 2): interior, lower, upper, ...
    n = c.size
    idx = np.arange(n)

    def F(x):
        return x**3 - c

    def J(x):
        return sp.csc_matrix((3.0 * x**2, (idx, idx)), shape=(n, n))

    return KnownProblem(
        name="boxvi", F=F, J=J, lb=lb, ub=ub,
        x0=np.zeros(n) if x0 is None else np.asarray(x0, float),
        solutions=[sol], source="separable box VI (closed form)",
    )


# ----------------------------------------------------------------------------- hard scalar ones
def degenerate_root(x0=None) -> KnownProblem:
    return KnownProblem(
        name="double_root",
        F=lambda x: np.array([x[0] ** 2 - 2.0 * x[0] + 1.0]),
        J=lambda x: np.array([[2.0 * x[0] - 2.0]]),
        lb=np.array([-np.inf]), ub=np.array([np.inf]),
        x0=np.array([3.0]) if x0 is None else np.asarray(x0, float),
        solutions=[np.array([1.0])], source="(x - 1)^2 = 0, x free",
    )


def billups(x0=None) -> KnownProblem:
    return KnownProblem(
        name="billups",
        F=lambda x: np.array([(x[0] - 1.0) ** 2 - 1.01]),
        J=lambda x: np.array([[2.0 * (x[0] - 1.0)]]),
        lb=np.zeros(1), ub=np.full(1, np.inf),
        x0=np.zeros(1) if x0 is None else np.asarray(x0, float),
        solutions=[np.array([1.0 + math.sqrt(1.01)])],
        source="Billups (1995); MCPLIB billups",
    )


def log_ncp(x0=None, c=(-3.0, -2.0, 0.5, 1.0), *, raise_errors=True) -> KnownProblem:
    """F_i = log(x_i) - c_i, x >= 0: undefined at x_i = 0 (raises ValueError when
    ``raise_errors``, else returns -inf/NaN).  Solution x = exp(c) (interior)."""
    c = np.asarray(c, dtype=float)
    n = c.size
    idx = np.arange(n)

    def F(x):
        if raise_errors:
            return np.array([math.log(xi) for xi in x]) - c  # ValueError at xi <= 0
        with np.errstate(all="ignore"):
            return np.log(x) - c

    def J(x):
        if raise_errors and np.any(x <= 0):
            raise ValueError("log undefined")
        with np.errstate(all="ignore"):
            return sp.csc_matrix((1.0 / x, (idx, idx)), shape=(n, n))

    return KnownProblem(
        name="log_ncp", F=F, J=J, lb=np.zeros(n), ub=np.full(n, np.inf),
        x0=np.full(n, 2.0) if x0 is None else np.asarray(x0, float),
        solutions=[np.exp(c)], source="log(x) - c (closed form)",
    )


def sqrt_ncp(x0=None) -> KnownProblem:
    """F(x) = sqrt(x - 1) + x - 3 on x >= 0: NaN for x < 1 (part of the box).  Solution 2."""

    def F(x):
        with np.errstate(all="ignore"):
            return np.sqrt(x - 1.0) + x - 3.0

    def J(x):
        with np.errstate(all="ignore"):
            return np.array([[0.5 / np.sqrt(x[0] - 1.0) + 1.0]])

    return KnownProblem(
        name="sqrt_ncp", F=F, J=J, lb=np.zeros(1), ub=np.full(1, np.inf),
        x0=np.array([1.05]) if x0 is None else np.asarray(x0, float),
        solutions=[np.array([2.0])], source="sqrt(x - 1) + x - 3 (closed form)",
    )


ALL_SOLVABLE = {
    "kojshin": kojima_shindo,
    "josephy": josephy,
    "mathiesen": mathiesen,
    "cournot2": cournot_duopoly,
    "nash5": nash_cournot_mss,
    "boxvi": separable_box_vi,
}


# ------------------------------------------------------------------ the homotopy's problems
def quadratic(D, A, b):
    """(F, J) of F(x) = D x^2 + A x + b (elementwise square), J in CSC form."""
    D, A, b = (np.asarray(v, dtype=float) for v in (D, A, b))

    def F(x):
        return D * x * x + A @ x + b

    def J(x):
        return sp.csc_matrix(np.diag(2.0 * D * x) + A)

    return F, J


# A one-dimensional MCP on the box [-3.04, 3.18] with F(x) = 0.27 x^2 - 0.69 x - 5.68 < 0
# on the whole box: its only solution is the upper bound.  The merit function has a
# stationary point over the box at the lower bound (F decreases there, so the Newton
# model pushes the wrong way and no descent direction stays in the box).
STATIONARY = dict(D=[0.27], A=[[-0.69]], b=[-5.68], lb=[-3.04], ub=[3.18], x0=[-2.9])


def stationary_quadratic():
    """(F, J, lb, ub, x0) of :data:`STATIONARY`: solution 3.18, the upper bound."""
    d = STATIONARY
    F, J = quadratic(d["D"], d["A"], d["b"])
    return F, J, np.array(d["lb"]), np.array(d["ub"]), np.array(d["x0"])


def diverging_free(n=2):
    """(F, J, lb, ub, x0) of F(x) = -x on free variables: the solution is 0, but the zero
    curve of H = lam (-x) + (1 - lam)(x - a) is x = (1 - lam) a / (1 - 2 lam), unbounded at
    lam = 1/2."""
    def F(x):
        return -x

    def J(x):
        return -sp.identity(x.size, format="csc")

    return F, J, np.full(n, -np.inf), np.full(n, np.inf), np.ones(n)
