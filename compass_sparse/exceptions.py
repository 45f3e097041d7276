"""The package's exception hierarchy.

Bad input is an exception; a failed solve is a status (see :mod:`compass_sparse.result`).
Every exception derives from :class:`CompassError`; input problems also derive from
``ValueError`` so that generic callers can catch them the usual way.
"""


class CompassError(Exception):
    """Base class of every error raised by compass_sparse."""


class ProblemError(CompassError, ValueError):
    """The problem definition is invalid (shapes, bounds, start point, names)."""


class ShapeError(ProblemError):
    """An array, F(x) or J(x) has the wrong shape, or the system is not square."""


class ModelError(ProblemError):
    """A model written in a modelling language (Pyomo, GAMSPy) cannot be turned into an MCP:
    a complementarity without a variable on either side, unmatched equations, a missing
    bound, an unsupported expression.  The message names the model component."""


class BoundsError(ProblemError):
    """Bounds are inconsistent (lb > ub, lb = +inf, ub = -inf) or contain NaN."""


class StartPointError(ProblemError):
    """The start point contains NaN or Inf."""


class EvaluationError(CompassError):
    """F or J could not be evaluated, or returned NaN/Inf, where a finite value is required
    (at the start point). Mid-solve evaluation failures are handled by stepping back and
    are reported in the Result, not raised."""


class JacobianPatternError(EvaluationError):
    """The structural sparsity pattern of J changed between calls."""


class OptionError(CompassError, ValueError):
    """An unknown option name or a value outside its documented range."""


class SingularBasisError(CompassError):
    """A basis could not be factorized even after rank repair (internal; the pivotal path
    turns it into a linear-solver code)."""
