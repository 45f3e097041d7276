"""Guarded evaluation of F and J during a solve.

Robustness is plain code: an exception or a NaN/Inf from the user's F or J at a trial
point rejects that point (the caller shortens the step, as PATH does with evaluation
errors) instead of aborting the solve.  Every rejected evaluation is counted.
"""
from __future__ import annotations

import numpy as np

from .exceptions import JacobianPatternError, ShapeError


class GuardedEvaluator:
    """F and J of an MCP with domain errors turned into ``None``."""

    def __init__(self, problem):
        self.problem = problem
        self.domain_errors = 0
        self.last_error: str = ""

    def f(self, z):
        try:
            f = self.problem.F(z)
        except (ShapeError, JacobianPatternError, KeyboardInterrupt):
            raise
        except Exception as exc:  # the user's F failed here: reject the point
            self.domain_errors += 1
            self.last_error = repr(exc)
            return None
        if not np.all(np.isfinite(f)):
            self.domain_errors += 1
            self.last_error = "F returned NaN/Inf"
            return None
        return f

    def jac(self, z, f=None):
        try:
            if f is not None and self.problem._jac is None:
                J = self.problem._jac_given_f(z, f)  # finite differences reuse F(z)
            else:
                J = self.problem.J(z)
        except (ShapeError, JacobianPatternError, KeyboardInterrupt):
            raise
        except Exception as exc:
            self.domain_errors += 1
            self.last_error = repr(exc)
            return None
        if not np.all(np.isfinite(J.data)):
            self.domain_errors += 1
            self.last_error = "J returned NaN/Inf"
            return None
        return J

    def fj(self, z):
        """(f, J) or (None, None).  One F and one J evaluation."""
        if self.problem._jac is True:
            try:
                f, J = self.problem.FJ(z)
            except (ShapeError, JacobianPatternError, KeyboardInterrupt):
                raise
            except Exception as exc:
                self.domain_errors += 1
                self.last_error = repr(exc)
                return None, None
            if not (np.all(np.isfinite(f)) and np.all(np.isfinite(J.data))):
                self.domain_errors += 1
                return None, None
            return f, J
        f = self.f(z)
        if f is None:
            return None, None
        J = self.jac(z, f)
        if J is None:
            return None, None
        return f, J
