"""The economics of a counterfactual: what changed between two equilibria of a CGE model.

Variables are classified from the model's homogeneity structure (no per-family tables):

* quantities (activity levels, Armington aggregates, utility indices): off the price ray;
* incomes (household incomes, tax revenue): on the ray, complementary to a row of degree 1
  (an income balance);
* prices (producer, Armington, factor and unit-expenditure prices): on the ray,
  complementary to a market-clearing row (degree 0).

Prices and incomes are in units of the numeraire (both equilibria fix the same one).

Welfare of household h (static models, which carry a utility index U and its unit
expenditure price PU): with homothetic preferences the expenditure function is
e(p, u) = u e(p), and the calibrated income identity M_h = Mbar_h PU_h U_h holds at every
equilibrium.  The Hicksian equivalent variation at the ``before`` prices is therefore

    EV_h = e(p0, u1) - e(p0, u0) = PU0_h Mbar_h (U1_h - U0_h) = M0_h (U1_h / U0_h - 1),

the money (numeraire units at the old prices) that, given at the old prices, would leave h
as well off as the counterfactual.  ``ev_percent`` = 100 (U1/U0 - 1), the same measure
relative to the old income.  For comparison the report also gives the income-based measure,
the change of real income M/PU (equal to the EV at an exact equilibrium).  Models without
household utility blocks (the dynamic Ramsey model, whose numeraire is the agent's income)
get the price, quantity and income changes only.
"""
from __future__ import annotations

import csv
import io
from dataclasses import dataclass

import numpy as np

__all__ = ["Change", "EconomicsReport", "Welfare", "economics_report"]


@dataclass(frozen=True)
class Change:
    """One variable's value in both equilibria."""

    name: str
    block: str
    kind: str  # 'price', 'quantity' or 'income'
    before: float
    after: float

    @property
    def change(self) -> float:
        return self.after - self.before

    @property
    def percent(self) -> float:
        """100 (after / before - 1); NaN when before is 0."""
        return 100.0 * (self.after / self.before - 1.0) if self.before != 0 else float("nan")


@dataclass(frozen=True)
class Welfare:
    """A household's welfare change (see the module docstring)."""

    household: str
    income_before: float
    income_after: float
    utility_before: float
    utility_after: float
    ev: float  #: equivalent variation, numeraire units at the old prices
    ev_percent: float  #: EV as a percentage of the old income
    real_income_percent: float  #: 100 ((M1/PU1) / (M0/PU0) - 1), income-based measure


@dataclass
class EconomicsReport:
    """Changes of every price, quantity and income, and each household's welfare."""

    changes: list
    welfare: list
    numeraire: str | None = None

    def of_kind(self, kind: str) -> list:
        return [c for c in self.changes if c.kind == kind]

    def largest(self, kind: str, k: int = 10) -> list:
        """The k variables of a kind with the largest absolute percent change."""
        rows = [c for c in self.of_kind(kind) if np.isfinite(c.percent)]
        return sorted(rows, key=lambda c: -abs(c.percent))[:k]

    def table(self, top: int = 10) -> str:
        """A plain-text report: welfare per household, a summary of each block, and the
        ``top`` largest price, quantity and income changes."""
        out = []
        if self.numeraire:
            out.append(f"prices and incomes in units of the numeraire: {self.numeraire}")
        if self.welfare:
            out.append("")
            out.append("welfare by household (EV: equivalent variation at the old prices)")
            out.append(f"  {'household':14s} {'income0':>11s} {'income1':>11s} {'EV':>11s} "
                       f"{'EV %':>8s} {'real inc %':>10s}")
            for w in self.welfare:
                out.append(f"  {w.household:14s} {w.income_before:11.4g} {w.income_after:11.4g}"
                           f" {w.ev:11.4g} {w.ev_percent:8.3f} {w.real_income_percent:10.3f}")
            tot = sum(w.ev for w in self.welfare)
            out.append(f"  {'total':14s} {'':11s} {'':11s} {tot:11.4g}")
        out.append("")
        out.append("change by block (% change: min / median / max)")
        blocks = dict.fromkeys(c.block for c in self.changes)
        for b in blocks:
            rows = [c for c in self.changes if c.block == b]
            pct = np.array([c.percent for c in rows if np.isfinite(c.percent)])
            if pct.size:
                out.append(f"  {b:6s} {rows[0].kind:9s} {len(rows):6d} vars   "
                           f"{pct.min():9.3f} / {np.median(pct):9.3f} / {pct.max():9.3f}")
        for kind in ("price", "quantity", "income"):
            big = self.largest(kind, top)
            if not big:
                continue
            out.append("")
            out.append(f"largest {kind} changes")
            out.append(f"  {'variable':22s} {'before':>11s} {'after':>11s} {'% change':>9s}")
            for c in big:
                out.append(f"  {c.name:22s} {c.before:11.5g} {c.after:11.5g} {c.percent:9.3f}")
        return "\n".join(out)

    def to_csv(self, file=None) -> str | None:
        """Every variable (kind, block, name, before, after, change, % change) and then
        every household's welfare, as CSV.  Writes to ``file`` (a path or a text file) or
        returns the text when ``file`` is None."""
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(["kind", "block", "name", "before", "after", "change", "percent"])
        for c in self.changes:
            w.writerow([c.kind, c.block, c.name, repr(c.before), repr(c.after),
                        repr(c.change), repr(c.percent)])
        for h in self.welfare:
            w.writerow(["welfare_ev", "U", h.household, repr(h.income_before),
                        repr(h.income_before + h.ev), repr(h.ev), repr(h.ev_percent)])
        text = buf.getvalue()
        if file is None:
            return text
        if hasattr(file, "write"):
            file.write(text)
        else:
            with open(file, "w", encoding="utf-8") as fh:
                fh.write(text)
        return None


def _kinds(model) -> np.ndarray:
    kinds = np.where(model.ray, np.where(model.degree == 1, "income", "price"), "quantity")
    return kinds


def economics_report(model, before, after) -> EconomicsReport:
    """What changed from equilibrium ``before`` to equilibrium ``after`` of ``model``.

    Parameters
    ----------
    model : CGEModel
        The counterfactual model (or the benchmark model: they share variables).
    before, after : array
        The two points, e.g. ``model.benchmark`` and ``solve_mcp(shocked.problem).x``.

    Returns
    -------
    EconomicsReport
        ``changes`` (one :class:`Change` per variable) and ``welfare`` (one
        :class:`Welfare` per household of a model with utility blocks ``U``, ``PU``, ``M``;
        empty otherwise).
    """
    before = np.asarray(before, dtype=float)
    after = np.asarray(after, dtype=float)
    if before.shape != (model.n,) or after.shape != (model.n,):
        raise ValueError(f"before and after must have the model's {model.n} entries; got "
                         f"{before.shape} and {after.shape}")
    kinds = _kinds(model)
    block_of = np.empty(model.n, dtype=object)
    for b, s in model.blocks.items():
        block_of[s] = b
    changes = [Change(model.names[i], block_of[i], str(kinds[i]), float(before[i]),
                      float(after[i])) for i in range(model.n)]
    welfare = []
    if all(b in model.blocks for b in ("U", "PU", "M")):
        U0, U1 = before[model.blocks["U"]], after[model.blocks["U"]]
        P0, P1 = before[model.blocks["PU"]], after[model.blocks["PU"]]
        M0, M1 = before[model.blocks["M"]], after[model.blocks["M"]]
        names = [model.names[i] for i in range(model.n)][model.blocks["M"]]
        for k, nm in enumerate(names):
            hh = nm[nm.index("[") + 1: -1] if "[" in nm else nm
            ratio = U1[k] / U0[k] if U0[k] != 0 else float("nan")
            real = (M1[k] / P1[k]) / (M0[k] / P0[k]) if M0[k] != 0 and P1[k] != 0 \
                else float("nan")
            welfare.append(Welfare(hh, float(M0[k]), float(M1[k]), float(U0[k]),
                                   float(U1[k]), float(M0[k] * (ratio - 1.0)),
                                   100.0 * (ratio - 1.0), 100.0 * (real - 1.0)))
    return EconomicsReport(changes, welfare, model.info.get("numeraire"))
