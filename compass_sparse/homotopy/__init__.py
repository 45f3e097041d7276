"""Probability-one homotopy on the smoothed normal map: the fallback when the stabilized
Newton method stalls at a stationary point of its merit function (Billups & Watson,
SIAM J. Optim. 12, 2002; Zhou & Yu, J. Ind. Manag. Optim. 7, 2011; Speight 1999).

The equation
------------
For the box B = [l, u] the normal map F_B(x) = F(pi(x)) + x - pi(x) vanishes exactly when
z = pi(x) solves the MCP (thesis §3.1).  It is only piecewise smooth, so we follow a
smoothed version.  With the smoothed plus function

    s_mu(r) = (r + sqrt(r^2 + 4 mu^2)) / 2       (Chen-Harker-Kanzow-Smale; s_0 = max(r, 0))

the smoothed projection is, row by row,

    both bounds   p_mu(x) = l + s_mu(x - l) - s_mu(x - u)
    lower only    p_mu(x) = l + s_mu(x - l)
    upper only    p_mu(x) = u - s_mu(u - x)
    free          p_mu(x) = x,

smooth in (x, mu) for mu > 0 with 0 < d p_mu / dx < 1 on bounded rows, and p_0 = pi.  The
smoothed normal map is G_mu(x) = F(p_mu(x)) + x - p_mu(x), with Jacobian
G_x = J(p) D + I - D, D = diag(p_mu'(x)).

The homotopy
------------
For a start point a (random in the box) and smoothing driven to 0 along the path,

    H_a(x, lam) = lam G_{mu(lam)}(x) + (1 - lam)(x - a),    mu(lam) = mu0 (1 - lam).

At lam = 0 the unique zero is x = a with H_x = I.  Because dH/da = -(1 - lam) I has full
rank for lam < 1, the parametrized Sard theorem says that for almost every a the zero set
of H_a in [0, 1) x R^n contains a smooth curve gamma_a starting at (a, 0) with no
bifurcations (this is the "probability one").  When the box is bounded, x - p_mu(x) points
outwards and F(p_mu(x)) stays bounded, so H_a has no zeros with large ||x||: gamma_a is
bounded and reaches lam = 1, where its limit points x* solve F_B(x*) = 0.  With infinite
bounds the curve stays bounded when the MCP has no "solution at infinity" (Zhou & Yu's
condition); otherwise it can diverge, and that is reported (``HomotopyStatus.DIVERGED``).

Path tracking
-------------
gamma_a is followed in its arclength s (so lam may decrease: turning points are passed
without special treatment) by a predictor-corrector method:

* tangent: the unit kernel vector of DH = [H_x, H_lam], from the bordered system
  [[H_x, H_lam], [v^T]] w = e_{n+1} with v the previous tangent, oriented so that
  w^T v > 0 (at the start v = e_{n+1}, so lam increases first);
* predictor: Euler step y_p = y + h tau;
* corrector: chord Newton iterations on {H(y) = 0, v^T (y - y_p) = 0} with the bordered
  matrix factorized at the last accepted point (one factorization per accepted step serves
  both the tangent and the corrector);
* step control (after Allgower & Georg): a corrector whose corrections do not contract
  (ratio > ``CONTRACTION_MAX``), whose first correction is long compared with the step, or
  that needs more than ``CORRECTOR_ITERATIONS`` iterations halves h and retries; an
  accepted step rescales h by the observed contraction and first correction against
  their nominal values (at most doubling it); h below ``homotopy_step_minimum`` ends the
  path.  Points are followed to the relative accuracy ``CORRECTOR_TOLERANCE`` only, judged
  by the estimated distance to the curve after the last correction
  (``CORRECTOR_ESTIMATE``).

The bordered matrix is factorized densely (LAPACK's getrf) when the Jacobian is dense or
small and by SuperLU otherwise (the border adds one dense row and column).  A dense
problem's tangent and each chord iteration are then one compiled call (triangular sweeps
on getrf's factors), around the evaluation of F; the array route serves the others.

The first path starts from ``homotopy_start``: the best point the stabilized Newton method
found before it stalled (the default), or the user's start point.  Later paths start from
random points drawn around the user's start point.

End game (Speight's hybrid)
---------------------------
Near the end of the path (lam >= ``homotopy_end_lambda``) every accepted point is handed to
Newton's method on the piecewise smooth normal map, x+ = x - (J D_B + I - D_B)^{-1} F_B(x),
D_B the 0/1 diagonal of pi' (Robinson's normal-map Newton), accepting only decreases of
||F_B||.  If Newton does not reach the tolerance the path resumes with a later switch
(the gap 1 - lam shrinks tenfold).  The caller may also pass a ``polish`` function (the
stabilized Newton method) that receives the end point of the path.

Every accepted path point and every end-game point is offered to the caller
(``on_point``), so the best point is kept whatever happens; a path that fails is followed
by a new one from a random point of the box, up to ``homotopy_path_limit`` paths.

Modules: ``smoothing`` (p_mu), ``bordered`` (the bordered LU), ``tracker`` (the
predictor-corrector, its compiled route and the end game), ``paths`` (the pass:
:func:`homotopy_pass`, :func:`track_paths`), ``outcome`` (:class:`HomotopyStatus`,
:class:`HomotopyOutcome`).
"""
from .outcome import HomotopyOutcome, HomotopyStatus
from .paths import homotopy_pass, track_paths
from .smoothing import SmoothedNormalMap

__all__ = ["HomotopyOutcome", "HomotopyStatus", "SmoothedNormalMap", "homotopy_pass",
           "track_paths"]
