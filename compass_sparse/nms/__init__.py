"""Non-monotone stabilization (NMS): the major-iteration loop (thesis §3.4; Dirkse & Ferris
1995; Ferris, Kanzow & Munson 1999).

Each major iteration linearizes F at z_k = pi(x_k) with the proximal perturbation

    M = J(z_k) + eps I,   q = F(z_k) - M z_k,

and walks the pivotal path from x_k (warm-started from the previous basis) to the Newton
point x_N.  Acceptance (merit Psi = 0.5 ||Phi_FB||^2):

* d-step: ||z_N - z_k||_inf <= Delta (Delta shrinks by ``nms_delta_shrink_factor``) and at
  most ``nms_mstep_frequency`` consecutive d-steps: accept without a descent test (fast
  Newton progress);
* m-step: Psi(z_N) <= R - sigma max(0, -grad Psi^T (z_N - z_k)), or (1 - sigma) R, where
  the reference value R is the largest merit of the last ``nms_memory_size`` checkpoints;
  an accepted m-step (or a d-step that beats R) becomes a checkpoint;
* watchdog: otherwise return to the last checkpoint and search the segment towards the
  Newton point computed there (line: convex combination of the z's; arc: projection of
  the combination of the x's), shrinking by ``nms_shrink_factor``;
* fallback: when the watchdog fails, the path fails without a usable point, or the
  watchdog limit is reached, take a Levenberg–Marquardt step and/or projected-gradient
  steps on Psi from the best point found.

With ``nms = False`` the same loop is a monotone line search: no d-steps, a memory of one
checkpoint and the reference value Psi(z_k), so every accepted step decreases the merit.

Restarts when progress stops follow :mod:`compass_sparse.nms.restarts`: PATH's three
configurations, then, as the thesis proposes, new points in the box and points near the
best one.
The best point is kept through everything and every exit returns it.

Major-iteration log (verbosity >= 2), fixed-width columns as in PATH:
``major minor func grad residual type prox inorm (label)`` — minor = pivots of this
path, func/grad = cumulative F/J evaluations, residual = ||Phi_FB||_2, type = two
letters: the path's code (S solved, R ray, C cycle, I pivot limit, N singular basis,
T tolerance lost, E error) and the step (D d-step, M m-step, O both tests passed,
W watchdog, G projected gradient, L Levenberg–Marquardt; ``-H``: a homotopy pass, counted
as one major iteration), prox = eps, inorm = ||Phi||_inf
with the worst row's name.  Crash lines: ``crash iter changes size residual step``.

Modules: ``solver`` (:class:`NMSSolver`: runs, restarts, the homotopy, the diagnosis;
the Python loop of the major iterations), ``compiled`` (the same loop's bookkeeping in
compiled calls), ``newton`` (the Newton point of a major iteration: linearization, path,
basis), ``best`` (the best point and the acceptance of every evaluated point), ``state``
(points, a run's state, the step tests), ``log`` (history and log lines),
``acceptance``, ``fallback``, ``restarts``, ``stationarity``.
"""
from .solver import NMSSolver
from .state import Outcome, Point

__all__ = ["NMSSolver", "Outcome", "Point"]
