"""The log never changes the arithmetic: a solve at verbosity 3 (major and minor logs)
returns the bits and counts of the same solve at verbosity 0, on every route -- the
compiled dense and sparse engines (which report their pivots from a record buffer), the
sparse basis,
the compiled and Python major iterations, restarts, an LCP -- and logs one minor line per
pivot it makes."""
from __future__ import annotations

import logging

import numpy as np
import pytest
import scipy.sparse as sp

import known_problems as kp

import compass_sparse as cs
import compass_sparse.generators as gen



def _record(r):
    return (r.status, r.message, r.x.tobytes(), r.fun.tobytes(), r.nit, r.minor_iterations,
            r.crash_iterations, r.restarts, r.nfev, r.njev, r.factorizations,
            r.basis_updates, r.gradient_steps, r.lm_steps, r.routes,
            [(h.nit, h.residual, h.step, h.pivots, h.prox) for h in r.history or []])


def _nonlinear(g):
    """The LCP of generator ``g`` with a small monotone nonlinearity added (an MCP)."""
    M, q, lb, ub = g.lcp
    M = sp.csc_matrix(M)

    def F(z):
        return M @ z + q + 0.1 * z ** 3 * (z > 0)

    def J(z):
        return sp.csc_matrix(M + sp.diags(0.3 * z ** 2 * (z > 0)))

    return cs.MCP(F, J, lb, ub, np.clip(np.zeros(q.size), lb, ub))


def _cases():
    k = kp.kojima_shindo()
    return [
        ("kojshin (dense engine)", (k.F, k.J, k.lb, k.ub, k.x0), {}),
        ("thesis n=50 (dense engine, pivots)", (gen.thesis_family(50, 2, 4).problem,), {}),
        ("thesis n=10 restarts", (gen.thesis_family(10, 2, 4).problem,), {"homotopy": "off"}),
        ("thesis n=10 restarts, Python loops", (gen.thesis_family(10, 2, 7).problem,),
         {"homotopy": "off", "engine": "reference"}),
        ("n=400 (dense engine above the dense basis' order)",
         (_nonlinear(gen.p_matrix_lcp(400, "banded", 3, "mixed")),), {"crash_method": "none"}),
        ("n=576 (sparse engine)", (_nonlinear(gen.obstacle_problem(24, 1)),),
         {"crash_method": "none"}),
        ("n=576 (sparse basis: the Python loop)", (_nonlinear(gen.obstacle_problem(24, 1)),),
         {"crash_method": "none", "path_basis": "sparse"}),
        ("traffic n=912 (sparse engine, 586 pivots)",
         (gen.traffic_equilibrium(8).problem,), {}),
    ]


@pytest.fixture
def minor_log():
    """The log records of the compass_sparse logger, whatever its configuration."""
    lines = []

    class Keep(logging.Handler):
        def emit(self, record):
            lines.append(record.getMessage())

    lg = logging.getLogger("compass_sparse")
    handler, level = Keep(), lg.level
    lg.addHandler(handler)
    lg.setLevel(logging.INFO)
    yield lines
    lg.removeHandler(handler)
    lg.setLevel(level)


@pytest.mark.parametrize("case", range(len(_cases())), ids=[c[0] for c in _cases()])
def test_verbosity_3_solves_the_silent_solves_bits(case, minor_log):
    name, args, opts = _cases()[case]
    quiet = cs.solve_mcp(*args, options={**opts, "verbosity": 0})
    # at verbosity 0 only the preprocessor's records reach the logger (the traffic
    # model's structural-rank warning and its summary: the logging module's levels)
    assert [s for s in minor_log if not s.startswith(("presolve:", "Preprocessor"))] == []
    minor_log.clear()
    loud = cs.solve_mcp(*args, options={**opts, "verbosity": 3})
    assert _record(loud) == _record(quiet), name
    if "(sparse engine" in name:
        assert quiet.routes["path"] == "sparse engine"
    pivots = [s for s in minor_log if s.startswith("minor") and "direct step" not in s]
    assert len(pivots) == loud.minor_iterations, name
    majors = _section(minor_log, "Major Iteration Log")
    majors = [s for s in majors if s[:5].strip().isdigit()]
    assert len(majors) == sum(1 for h in loud.history[1:] if h.step != ""), name


def _section(lines, title):
    """The lines of the log's sections called ``title`` (compass_sparse.nms.log)."""
    out, inside = [], False
    for s in lines:
        if s in ("Crash Log", "Major Iteration Log", "Homotopy Log"):
            inside = s == title
        elif inside:
            out.append(s)
    return out


def test_a_logged_lcp_takes_the_silent_lcps_pivots(minor_log):
    g = gen.p_matrix_lcp(60, "banded", 2, "mixed")
    M, q, lb, ub = g.lcp
    opts = {"crash_method": "none"}
    quiet = cs.solve_lcp(M, q, lb, ub, options=opts)
    loud = cs.solve_lcp(M, q, lb, ub, options={**opts, "verbosity": 3})
    assert quiet.minor_iterations > 0 and quiet.routes["path"] == "dense engine"
    assert _record(loud) == _record(quiet)
    pivots = [s for s in minor_log if s.startswith("minor") and "direct step" not in s]
    assert len(pivots) == loud.minor_iterations


def _untimed(message):
    """A log message without its wall-clock figures (the summary's time and passes)."""
    return "\n".join(s for s in message.split("\n") if not s.startswith(("time", "passes")))


def test_the_compiled_and_python_major_iterations_write_the_same_log(minor_log):
    """verbosity 2: the compiled major iterations report each finished iteration to the
    log from Python, the same line the Python loop writes."""
    logs = {}
    for engine in ("auto", "reference"):
        minor_log.clear()
        for seed in (1, 4, 5):
            cs.solve_mcp(gen.thesis_family(10, 2, seed).problem,
                         options={"verbosity": 2, "engine": engine, "homotopy": "off"})
        logs[engine] = [_untimed(s) for s in minor_log]
    assert len(logs["auto"]) > 30 and logs["auto"] == logs["reference"]
