"""Plots of solves and benchmarks (needs matplotlib: ``pip install compass-sparse[plot]``).

matplotlib is imported only when a function here is called, so ``import compass_sparse``
never needs it.

* :func:`convergence` draws ``Result.history``: ||Phi_FB||_2 against the major iteration
  and against time, on a log scale, with the convergence tolerance as a dashed line.
* :func:`performance_profile` draws Dolan–Moré performance profiles: for solver s and
  instance p with cost t_{p,s} (inf = failure), the ratio r_{p,s} = t_{p,s} / min_s t_{p,s}
  and the profile rho_s(tau) = (number of p with r_{p,s} <= tau) / (number of instances),
  a step function of tau >= 1.
  rho_s(1) is the share of instances on which s is fastest, rho_s(inf) its success rate.
"""
from __future__ import annotations

import numpy as np

__all__ = ["convergence", "performance_profile", "profile_curve"]


def _pyplot():
    # matplotlib picks a non-interactive backend by itself when there is no display.
    try:
        # (matplotlib: an optional extra)
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - the plot extra installs it
        raise ImportError("compass_sparse.plot needs matplotlib: "
                          "pip install 'compass-sparse[plot]'") from exc
    return plt


def convergence(result, *, tolerance=None, axes=None, title=None):
    """Residual against major iteration (left) and against seconds (right).

    Parameters
    ----------
    result : Result or sequence of Iteration
        A solve's result (its ``history`` is drawn) or a history itself.
    tolerance : float, optional
        Drawn as a dashed line; default the result's convergence tolerance.
    axes : pair of matplotlib Axes, optional
        Where to draw; default a new figure with two panels.
    title : str, optional
        Figure title.

    Returns
    -------
    matplotlib.figure.Figure
    """
    history = getattr(result, "history", result)
    if not history:
        raise ValueError("no iteration history to plot: the stabilized Newton method did "
                         "not run (solved by the preprocessor, the crash or one path)")
    if tolerance is None:
        tolerance = getattr(result, "tolerance", None)
    plt = _pyplot()
    if axes is None:
        fig, axes = plt.subplots(1, 2, figsize=(9, 3.5), sharey=True)
    else:
        fig = axes[0].figure
    it = np.array([h.nit for h in history])
    res = np.array([max(h.residual, 1e-300) for h in history])
    t = np.array([h.time for h in history])
    for ax, xs, label in ((axes[0], it, "major iteration"), (axes[1], t, "seconds")):
        ax.semilogy(xs, res, marker="o", markersize=3)
        if tolerance is not None:
            ax.axhline(tolerance, linestyle="--", color="grey", linewidth=1)
        ax.set_xlabel(label)
        ax.grid(True, which="major", alpha=0.3)
    axes[0].set_ylabel(r"$\|\Phi_{FB}\|_2$")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig


def profile_curve(costs: np.ndarray, taus: np.ndarray) -> np.ndarray:
    """Dolan–Moré profiles: ``costs`` is (instances, solvers) with inf for failures;
    returns rho, (len(taus), solvers).  Instances that every solver failed count as
    failures for all (they stay in the count of instances)."""
    costs = np.asarray(costs, dtype=float)
    best = np.min(costs, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(np.isfinite(costs), costs / best[:, None], np.inf)
    ratio = np.where(np.isfinite(best)[:, None], ratio, np.inf)
    solved = np.isfinite(ratio)
    return np.array([np.mean(solved & (ratio <= tau), axis=0) for tau in taus])


def performance_profile(costs, labels, *, ax=None, tau_max=None, title=None,
                        xlabel="performance ratio tau (time / best time)"):
    """Draw Dolan–Moré performance profiles of several solvers.

    Parameters
    ----------
    costs : array (instances, solvers)
        Cost of each solver on each instance (e.g. seconds); inf or NaN = failure.
    labels : sequence of str
        One label per solver (column).
    ax : matplotlib Axes, optional
    tau_max : float, optional
        Right end of the tau axis (log scale); default the largest finite ratio times 1.5.

    Returns
    -------
    matplotlib.axes.Axes
    """
    costs = np.asarray(costs, dtype=float)
    costs = np.where(np.isnan(costs), np.inf, costs)
    if costs.ndim != 2 or costs.shape[1] != len(labels):
        raise ValueError(f"costs has shape {costs.shape}; expected (instances, {len(labels)})")
    plt = _pyplot()
    if ax is None:
        _, ax = plt.subplots(figsize=(5, 3.5))
    best = np.min(costs, axis=1)
    finite = np.isfinite(costs) & np.isfinite(best)[:, None]
    ratios = costs[finite] / np.broadcast_to(best[:, None], costs.shape)[finite]
    if tau_max is None:
        tau_max = 1.5 * float(ratios.max()) if ratios.size else 10.0
    taus = np.geomspace(1.0, max(tau_max, 1.01), 400)
    rho = profile_curve(costs, taus)
    for j, lab in enumerate(labels):
        ax.step(taus, rho[:, j], where="post", label=lab)
    ax.set_xscale("log")
    ax.set_ylim(0.0, 1.02)
    ax.set_xlabel(xlabel)
    ax.set_ylabel("share of instances")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="lower right")
    if title:
        ax.set_title(title)
    return ax
