"""The restart schedule of the stabilized Newton method (PATH; thesis §3.4).

When a run of crash + NMS stops making progress, the solver restarts.  Restart k
(k = 0, 1, ...) uses

* k = 0, 1, 2: PATH's three restart configurations, from the user's start point --
  (0) a proximal perturbation 0.01 min(1, r) without crash, r the best residual at the
  first restart; (1) no perturbation, a short memory and an m-step every step, no crash;
  (2) the crash with more basis changes allowed and arc searches everywhere;
* then alternately (k even) crash + NMS from a random point of the box, and (k odd) the
  perturbation of configuration 0 from a point near the best one found (the thesis'
  proposal for problems where every restart from the start point fails alike).
"""
from __future__ import annotations

__all__ = ["RestartSchedule", "FROM_START", "FROM_RANDOM", "FROM_NEAR_BEST"]

FROM_START, FROM_RANDOM, FROM_NEAR_BEST = "start", "random", "near best"


def path_configurations(residual: float) -> list:
    """PATH's three restart configurations (option changes)."""
    return [
        dict(proximal_perturbation=0.01 * min(1.0, residual), crash_method="none",
             nms_initial_reference_factor=2.0),
        dict(proximal_perturbation=0.0, crash_method="none", crash_perturb=False,
             nms_initial_reference_factor=10.0, nms_memory_size=2, nms_mstep_frequency=1),
        dict(crash_method="pnewton", crash_nbchange_limit=10, nms_initial_reference_factor=2.0,
             crash_searchtype="arc", nms_searchtype="arc", gradient_searchtype="arc"),
    ]


class RestartSchedule:
    """``plan(k, best_residual) -> (options, where)`` for restart k (see the module)."""

    def __init__(self, options):
        self.options = options
        self.configs = None

    def plan(self, k: int, best_residual: float):
        if self.configs is None:  # fixed at the first restart
            self.configs = path_configurations(best_residual)
        if k < len(self.configs):
            return self.options.replace(**self.configs[k]), FROM_START
        if k % 2 == 0:
            return (self.options.replace(crash_method="pnewton", crash_minimum_dimension=1),
                    FROM_RANDOM)
        return self.options.replace(**self.configs[0]), FROM_NEAR_BEST


