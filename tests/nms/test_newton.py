"""The Newton step of a major iteration (compass_sparse.nms.newton): what it makes and when."""

from __future__ import annotations

import known_problems as kp
import numpy as np

from compass_sparse import solve_mcp


def test_a_solve_the_crash_ends_builds_no_newton_linearizer(monkeypatch):
    """The Newton linearizer (the index arrays of J + eps I) is made at the first major
    iteration: a solve that the crash ends builds none (cournot2), one with major
    iterations builds it, with the same point as before this change (kojshin)."""
    from compass_sparse.path.linearize import Linearizer

    built = []
    real = Linearizer.__init__
    monkeypatch.setattr(Linearizer, "__init__",
                        lambda self, J: built.append(1) or real(self, J))
    k = kp.cournot_duopoly()
    r = solve_mcp(k.F, k.J, k.lb, k.ub, k.x0)
    assert r.success and r.nit == 0 and r.crash_iterations > 0 and built == []
    k = kp.kojima_shindo()
    r = solve_mcp(k.F, k.J, k.lb, k.ub, k.x0, options={"crash_method": "none"})
    assert r.success and r.nit > 0 and len(built) == 1
    assert min(np.max(np.abs(r.x - s)) for s in k.solutions) < 1e-6
