"""Can GAMS run here?  One probe of GAMS' state, cached per process.

The GAMSPy link (:mod:`compass_sparse.interfaces.gamspy`) and the PATH reference runner
(:mod:`compass_sparse.interfaces.path_gamspy`) need a GAMS system that runs, and GAMS runs
only under a valid licence.  GAMSPy ships a time-limited demo licence; once it has expired,
every GAMS job ends with

    *** Time-limited license expired 1 days ago
    *** Status: Terminated due to a licensing error

and GAMSPy reports only that GAMS "is in a bad state".  A licence is an external condition,
like a missing optional extra, so it is probed once, by the smallest GAMS job there is (one
scalar, about 20 ms), and every caller asks the probe instead of finding out from a failure:

* :func:`gams_state` -- the cached :class:`GamsState` (``condition`` one of
  ``"not-installed"``, ``"runs"``, ``"licence-refused"``, ``"failed"``), with GAMS' own
  licence lines and a one-line ``reason`` (what the test suite's skip markers print);
* :func:`require_gams` -- raise :class:`~compass_sparse.exceptions.GamsLicenseError` unless
  GAMS runs;
* :func:`gams_refusals` -- a context manager around GAMSPy calls that turns a refusal by
  GAMS (expired or invalid licence, a model above the licence's size limit) into
  :class:`~compass_sparse.exceptions.GamsLicenseError` quoting GAMS' licence lines, and leaves
  every other error alone.

Where GAMS lives and which licence it uses follow GAMSPy's own rules: the system directory
is ``$GAMSPY_GAMS_SYSDIR`` or the ``gamspy_base`` package; the licence is
``$GAMSPY_LICENSE_PATH``, else a licence installed by ``gamspy install license`` (GAMSPy's
user folder), else the demo licence in the system directory.
"""
from __future__ import annotations

import contextlib
import datetime as _dt
import os
import re
import subprocess
import sys
import tempfile
from dataclasses import dataclass

from ..exceptions import GamsLicenseError

__all__ = ["GamsState", "gams_state", "gams_refusals", "probe_gams", "require_gams"]

#: Seconds the probe job may take before GAMS counts as not running (a healthy job: ~20 ms;
#: the first run on a cold disk can take a few seconds).
PROBE_TIMEOUT = 60.0

#: What a user can do about a refused licence; part of every GamsLicenseError's message.
LICENCE_ADVICE = (
    "GAMS (and with it GAMSPy's models and the PATH solver) runs only under a valid "
    "licence. Install one with `gamspy install license <access code or licence file>`, or "
    "point GAMSPY_LICENSE_PATH at a licence file; `gamspy show license` prints the licence "
    "in use. compass_sparse itself needs no licence: solve the model with solve_mcp, or "
    "write it with the Pyomo link.")

_STATE: GamsState | None = None
_LICENCE_WORD = re.compile(r"licen[cs]e", re.I)
_EXPIRED = re.compile(r"expired\s+(\d+)\s+days?\s+ago", re.I)
_SIZE = re.compile(r"(limit|too large|exceed)", re.I)


@dataclass(frozen=True)
class GamsState:
    """What a trivial GAMS job showed about this machine.

    ``condition`` is one of

    * ``"not-installed"``: no GAMS system (GAMSPy's ``gamspy_base`` is absent);
    * ``"runs"``: the job ran, so models within the licence's limits can be solved;
    * ``"licence-refused"``: GAMS stopped the job because of its licence (expired, invalid,
      missing); ``licence_lines`` quotes GAMS;
    * ``"failed"``: GAMS did not run for another reason (``detail`` says which).
    """

    condition: str
    reason: str
    licence_lines: tuple[str, ...] = ()
    detail: str = ""
    sysdir: str | None = None
    licence_path: str | None = None
    expired_on: _dt.date | None = None

    @property
    def runs(self) -> bool:
        return self.condition == "runs"

    def error(self, doing: str = "run GAMS") -> GamsLicenseError:
        """The GamsLicenseError a caller raises when it needs GAMS and this state refuses."""
        return GamsLicenseError(
            f"GAMS cannot {doing}: {self.reason}.", lines=self.licence_lines,
            kind="expired" if self.expired_on is not None else "licence",
            advice=LICENCE_ADVICE)


# --------------------------------------------------------------------------- the probe
def _sysdir() -> str | None:
    env = os.environ.get("GAMSPY_GAMS_SYSDIR")
    if env:
        return env
    try:
        # (GAMSPy: an optional extra)
        import gamspy_base
    except Exception:
        return None
    return getattr(gamspy_base, "directory", None) or os.path.dirname(gamspy_base.__file__)


def _licence_path(sysdir: str) -> str | None:
    """The licence GAMSPy would hand to GAMS; None: GAMS' default (the system directory's)."""
    env = os.environ.get("GAMSPY_LICENSE_PATH")
    if env:
        return env
    home = os.path.expanduser("~")
    if sys.platform == "darwin":
        user = os.path.join(home, "Library", "Application Support", "GAMSPy")
    elif sys.platform.startswith("win"):
        user = os.path.join(home, "Documents", "GAMSPy")
    else:
        user = os.path.join(home, ".local", "share", "GAMSPy")
    installed = os.path.join(user, "gamspy_license.txt")
    return installed if os.path.isfile(installed) else None


def licence_lines(text: str) -> tuple[str, ...]:
    """GAMS' own lines about its licence in a log or error text: the lines that name the
    licence and the job's ``Status`` line, stripped, in order, without repeats."""
    out: list[str] = []
    for line in text.splitlines():
        s = line.strip()
        if not s:
            continue
        if _LICENCE_WORD.search(s) or s.lstrip("*").strip().startswith("Status:"):
            if s not in out:
                out.append(s)
    return tuple(out)


def _expiry(lines, today: _dt.date) -> _dt.date | None:
    for s in lines:
        m = _EXPIRED.search(s)
        if m:
            return today - _dt.timedelta(days=int(m.group(1)))
    return None


def probe_gams(sysdir: str | None = None, *, timeout: float = PROBE_TIMEOUT) -> GamsState:
    """Run the smallest GAMS job (one scalar, displayed) and classify what happened.

    Uncached; :func:`gams_state` is the cached form every caller uses.  ``sysdir`` defaults
    to GAMSPy's system directory (``$GAMSPY_GAMS_SYSDIR`` or the ``gamspy_base`` package).
    """
    sysdir = sysdir or _sysdir()
    if sysdir is None:
        return GamsState("not-installed", "GAMS is not installed (optional extra: "
                         "pip install compass-sparse[gams])")
    exe = os.path.join(sysdir, "gams.exe" if sys.platform.startswith("win") else "gams")
    if not os.path.isfile(exe):
        return GamsState("not-installed", f"GAMS is not installed: no GAMS executable in "
                         f"{sysdir}", sysdir=sysdir)
    licence = _licence_path(sysdir)
    today = _dt.date.today()
    with tempfile.TemporaryDirectory(prefix="compass_gams_probe_") as work:
        with open(os.path.join(work, "probe.gms"), "w") as fh:
            fh.write("scalar probe / 1 /;\ndisplay probe;\n")
        cmd = [exe, "probe.gms", "lo=3", f"curDir={work}"]
        if licence:
            cmd.append(f"license={licence}")
        try:
            run = subprocess.run(cmd, cwd=work, capture_output=True, text=True,
                                 timeout=timeout, stdin=subprocess.DEVNULL)
        except subprocess.TimeoutExpired:
            return GamsState("failed", f"GAMS did not finish a trivial job within {timeout:g} s",
                             sysdir=sysdir, licence_path=licence)
        except OSError as exc:
            return GamsState("failed", f"GAMS could not be started: {exc}", sysdir=sysdir,
                             licence_path=licence)
        log = run.stdout + run.stderr
        try:
            with open(os.path.join(work, "probe.lst"), errors="replace") as fh:
                listing = fh.read()
        except OSError:
            listing = ""
    lines = licence_lines(log)
    refused = bool(lines) and any(
        "licens" in s.lower() and ("error" in s.lower() or "expired" in s.lower()
                                   or "invalid" in s.lower() or "cannot" in s.lower())
        for s in lines)
    if refused or run.returncode == 7:  # 7: GAMS' return code for a licence error
        expired = _expiry(lines, today)
        if expired is not None:
            why = f"time-limited licence expired {expired.isoformat()}"
        else:
            first = next((s for s in lines if "error" in s.lower() or "invalid" in s.lower()),
                         lines[0] if lines else f"return code {run.returncode}")
            why = "licence refused (" + first.lstrip("* ").rstrip(":") + ")"
        return GamsState("licence-refused", why, licence_lines=lines, sysdir=sysdir,
                         licence_path=licence, expired_on=expired,
                         detail=(log + "\n" + listing)[-4000:])
    if run.returncode != 0 or "probe" not in listing.lower():
        return GamsState("failed", f"GAMS failed on a trivial job (return code "
                         f"{run.returncode})", licence_lines=lines, sysdir=sysdir,
                         licence_path=licence, detail=log[-4000:])
    return GamsState("runs", "GAMS runs", licence_lines=lines, sysdir=sysdir,
                     licence_path=licence)


def gams_state(refresh: bool = False) -> GamsState:
    """The probe's verdict, cached for the process (``refresh`` probes again)."""
    global _STATE
    if _STATE is None or refresh:
        _STATE = probe_gams()
    return _STATE


def require_gams(doing: str = "run GAMS") -> GamsState:
    """The state when GAMS runs.  Otherwise raise GamsLicenseError when GAMS refused its
    licence, ImportError when GAMS is not installed, RuntimeError when it failed to run."""
    st = gams_state()
    if st.runs:
        return st
    if st.condition == "licence-refused":
        raise st.error(doing)
    if st.condition == "not-installed":
        raise ImportError(f"cannot {doing}: {st.reason}")
    raise RuntimeError(f"cannot {doing}: {st.reason}\n{st.detail}")


# --------------------------------------------------------------------------- refusals
def refusal_from(exc: BaseException, log: str = "", doing: str = "run GAMS"
                 ) -> GamsLicenseError | None:
    """The GamsLicenseError behind a failed GAMSPy call, or None when the failure is not
    GAMS refusing its licence.

    GAMSPy's message need not say "licence" (an expired licence surfaces as "GAMS is in a
    bad state"), so the probe is asked again; a model above the licence's size limit is
    recognised by GAMS' own words in the message or the log."""
    text = f"{exc}\n{log}"
    lines = licence_lines(text)
    if lines and any(_SIZE.search(s) for s in lines):
        return GamsLicenseError(
            f"GAMS cannot {doing}: the model is larger than the licence allows "
            "(GAMSPy's free licence: at most 1000 rows and columns for an MCP).",
            lines=lines, kind="size", advice=LICENCE_ADVICE)
    st = gams_state(refresh=True)
    if st.condition == "licence-refused":
        return st.error(doing)
    if lines:
        return GamsLicenseError(f"GAMS cannot {doing}: it refused its licence.",
                                lines=lines, kind="licence", advice=LICENCE_ADVICE)
    return None


@contextlib.contextmanager
def gams_refusals(doing: str = "run GAMS", log=None):
    """Around GAMSPy calls: a refusal by GAMS becomes GamsLicenseError (GAMS' lines quoted,
    the original exception chained); every other exception passes unchanged.  ``log``: a
    callable returning the GAMS log text written so far (searched for GAMS' own lines)."""
    try:
        yield
    except GamsLicenseError:
        raise
    except Exception as exc:
        err = refusal_from(exc, log() if log is not None else "", doing)
        if err is None:
            raise
        raise err from exc
