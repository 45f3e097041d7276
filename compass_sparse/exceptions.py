"""The package's exception hierarchy.

Bad input is an exception; a failed solve is a status (see :mod:`compass_sparse.status`).
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


class ResultsFolderError(CompassError):
    """A batch's results folder cannot be used as asked: it holds the results of another
    model (:class:`ModelMismatchError`) or another batch is writing to it
    (:class:`FolderLockedError`).  The message names the folder and what to do."""


class ModelMismatchError(ResultsFolderError):
    """A batch was asked to resume in a results folder whose stored model fingerprint
    differs from its model's (sizes, names, data, the tolerance): ``differences`` lists
    what differs, as (what, here, in the folder)."""

    def __init__(self, message, differences=()):
        super().__init__(message)
        self.differences = tuple(differences)


class FolderLockedError(ResultsFolderError):
    """Another batch holds the results folder's lock (``owner``: its pid, host and start
    time, as written in the lock file)."""

    def __init__(self, message, owner=None):
        super().__init__(message)
        self.owner = owner or {}


class SingularBasisError(CompassError):
    """A basis could not be factorized even after rank repair (internal; the pivotal path
    turns it into a linear-solver code)."""



class FactorBudgetError(CompassError):
    """A factorization was not started: its symbolic estimate exceeds the time left
    (``kind == "time"``) or the memory allowed (``kind == "memory"``).  Internal: a solve
    turns it into ``Status.TIME_LIMIT`` or ``Status.MEMORY_LIMIT``."""

    def __init__(self, kind, message):
        super().__init__(message)
        self.kind = kind


class GamsLicenseError(CompassError):
    """GAMS refused to run under its licence: the licence expired or is invalid
    (``kind`` ``"expired"`` or ``"licence"``), or a model is larger than the licence allows
    (``kind == "size"``).  Only the GAMSPy link and the PATH reference runner raise it;
    ``lines`` holds GAMS' own lines about its licence, which the message quotes."""

    def __init__(self, message, lines=(), kind="licence", advice=""):
        self.lines = tuple(lines)
        self.kind = kind
        text = message
        if self.lines:
            text += "\nGAMS says:\n" + "\n".join("    " + s for s in self.lines)
        if advice:
            text += "\n" + advice
        super().__init__(text)
