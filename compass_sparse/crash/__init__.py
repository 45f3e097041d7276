"""Crash pass: projected Newton to guess the active set (thesis §2.5; Dirkse & Ferris 1997).

At z_k in the box, the *fixed* indices are those at a bound whose F has the sign that keeps
them there,

    A = {i : (z_i = l_i and F_i >= 0) or (z_i = u_i and F_i <= 0)},   I = complement,

and the direction solves the reduced Newton system J_II d_I = F_I (d_A = 0), perturbed to
J_II + eps I when J_II is singular (Billups).  The search is along the projected path
z(alpha) = pi(z_k - alpha d) (``crash_searchtype = "arc"``; "line" searches the segment
z_k + alpha (pi(z_k - d) - z_k) instead), alpha = 1, 1/2, 1/4, ..., accepting the first
alpha with

    ||F_B(x(alpha))|| <= (1 - sigma alpha) ||F_B(x(0))||,

where x(alpha) is the point with pi(x) = z(alpha) of least normal-map norm: the normal cone
at z(alpha) absorbs the part of F that points out of the box (thesis (2.5.5)-(2.5.9)).
The crash stops when the active set stops changing (``crash_nbchange_limit``), the
decrease is below sigma, alpha < ``crash_stepsize_minimum``, a step would raise ||Phi||
above its start's (:data:`~compass_sparse.crash.outcome.RAISED`), or after
``crash_iteration_limit`` steps; it is skipped below ``crash_minimum_dimension``.
One factorization of J_II and one Jacobian per iteration: it is a Newton method on the
current face, which is why it finds the active set of well-behaved large problems in a
few steps.  When the inactive set moved by at most ``REUSE_MAX_CHANGES`` indices, the step
is first sought by GMRES preconditioned with the previous step's factors (an inexact
Newton step; see :func:`compass_sparse.crash.reduced.reuse_solve`) and J_II is factored
only when that fails: on the
large CGE models a factorization costs as much as tens of solves with old factors.

Modules: ``driver`` (:func:`crash`: the route, the BLAS block), ``projected_newton`` (the
Python loop), ``compiled`` (the same loop in compiled calls for problems whose blocks are
all dense), ``reduced`` (the reduced Newton systems), ``outcome`` (:class:`CrashResult`).
"""
from .driver import crash
from .outcome import CrashResult

__all__ = ["CrashResult", "crash"]
