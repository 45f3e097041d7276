"""Bad declarations are errors in the modeller's terms (names of blocks, sectors and
commodities), all subclasses of compass_sparse.exceptions.ModelError."""
import numpy as np
import pytest

from compass_sparse.exceptions import ModelError
from compass_sparse.mge import DeclarationError, Model, UnbalancedBenchmark


def _base():
    m = Model()
    X = m.sector("X")
    PX, PL = m.commodity("PX"), m.commodity("PL")
    RA = m.consumer("RA")
    return m, X, PX, PL, RA


def test_errors_are_model_errors():
    assert issubclass(DeclarationError, ModelError)
    assert issubclass(UnbalancedBenchmark, ModelError)


def test_unknown_commodity_in_a_block():
    m, X, _PX, _PL, _RA = _base()
    other = Model().commodity("PZ")
    with pytest.raises(DeclarationError, match="PZ.*not a commodity of this model"):
        m.production(X).output(other, 10)
    with pytest.raises(DeclarationError, match="X is a sector, not a commodity"):
        m.production(X).input(X, 10)
    with pytest.raises(DeclarationError, match="has no element 'zz'"):
        m.commodities("P", ["a", "b"])["zz"]


def test_negative_reference_quantity_names_block_and_commodity():
    m, X, PX, PL, RA = _base()
    m.production(X).output(PX, 10).input(PL, -5)
    m.demand(RA).final(PX, 10).endowment(PL, 10)
    with pytest.raises(DeclarationError, match=r"X.*negative reference quantity -5 of PL"):
        m.compile()


def test_commodity_with_no_market():
    m, X, PX, PL, RA = _base()
    m.commodity("PUNUSED")
    m.production(X).output(PX, 10).input(PL, 10)
    m.demand(RA).final(PX, 10).endowment(PL, 10)
    with pytest.raises(DeclarationError, match="PUNUSED has no market"):
        m.compile()


def test_sector_without_block_and_auxiliary_without_constraint():
    m, X, PX, PL, RA = _base()
    m.demand(RA).final(PX, 10).endowment(PL, 10)
    with pytest.raises(DeclarationError, match="X has no production block"):
        m.compile()
    m.production(X).output(PX, 10).input(PL, 10)
    m.auxiliary("T")
    with pytest.raises(DeclarationError, match="T has no constraint"):
        m.compile()


def test_block_without_inputs():
    m, X, PX, PL, RA = _base()
    m.production(X).output(PX, 10).input(PL, 0.0)
    m.demand(RA).final(PX, 10).endowment(PL, 10)
    with pytest.raises(DeclarationError, match="production block of X has no inputs"):
        m.compile()


def test_unbalanced_benchmark_names_the_worst_rows():
    m, X, PX, PL, RA = _base()
    m.production(X).output(PX, 10).input(PL, 9)
    m.demand(RA).final(PX, 10).endowment(PL, 9)
    check = m.benchmark()
    assert check.by_block["zero_profit"] == (pytest.approx(1.0), "zero_profit:X")
    with pytest.raises(UnbalancedBenchmark, match=r"zero_profit: 1 at zero_profit:X"):
        check.require(1e-8)


def test_bad_nests_elasticities_and_shapes():
    m, X, PX, PL, _RA = _base()
    with pytest.raises(DeclarationError, match="unknown parent 'nope'"):
        m.production(X, nests={"va": ("nope", 1.0)})
    with pytest.raises(DeclarationError, match="unknown nest 'vb'"):
        m.production(X).input(PL, 1.0, nest="vb")
    with pytest.raises(DeclarationError, match="cannot depend on variables"):
        m.production(X, s=PX)
    Y = m.sectors("Y", ["a", "b"])
    P = m.commodities("P", ["a", "b", "c"])
    with pytest.raises(DeclarationError, match=r"shape \(3, 2\), expected \(2, 3\)"):
        m.production(Y).input(P, np.ones((3, 2)))
    with pytest.raises(DeclarationError, match="3 elements for 2 owners"):
        m.production(Y).input(P, np.ones(2))
    m2, X2, PX2, PL2, RA2 = _base()
    m2.production(X2, s=-1.0).output(PX2, 10).input(PL2, 10)
    m2.demand(RA2).final(PX2, 10).endowment(PL2, 10)
    with pytest.raises(DeclarationError, match="must be >= 0"):
        m2.compile()


def test_names_and_constraints_are_checked():
    m, X, PX, _PL, _RA = _base()
    with pytest.raises(DeclarationError, match="already used"):
        m.sector("X")
    with pytest.raises(DeclarationError, match="paired with an auxiliary"):
        m.constraint(PX, PX - 1)
    T = m.auxiliary("T")
    m.constraint(T, T - 1)
    with pytest.raises(DeclarationError, match="already has a constraint"):
        m.constraint(T, T - 2)
    with pytest.raises(DeclarationError, match="goes to 2 consumers"):
        m.production(X).output(PX, 1, taxes=[(m.consumers("H", ["a", "b"]), 0.1)])


def test_prune_drops_data_less_sectors_and_commodities():
    """With prune=True a sector with no data and an untraded commodity are held at their
    start values instead of being errors (as a dataset's zero rows need)."""
    m = Model(prune=True)
    Y = m.sectors("Y", ["a", "b"])
    P = m.commodities("P", ["a", "b"])
    L = m.commodity("PL")
    H = m.consumer("H")
    m.production(Y).output(P, [10.0, 0.0]).input(L, [10.0, 0.0])
    m.demand(H).final(P["a"], 10).endowment(L, 10)
    st, _ = m.compile()
    assert sorted(st.pruned.tolist()) == [int(Y.cols[1]), int(P.cols[1])]
    sol = m.solve()
    assert sol.success and sol.value(Y["b"]) == 1.0 and sol.value(P["b"]) == 1.0


def test_tax_receivers_one_per_owner_or_per_entry():
    """A tax may go to one consumer, to one per owner, or to one per (owner, commodity)
    entry: each government's income at the benchmark is the revenue routed to it."""
    m = Model()
    Y = m.sectors("Y", ["a", "b"])
    P, F = m.commodities("P", ["a", "b"]), m.commodities("F", ["l", "k"])
    HH = m.consumer("HH")
    G = m.consumers("G", ["g1", "g2", "g3", "g4"])
    q = np.array([[20.0, 30.0], [40.0, 10.0]])
    rates = np.array([0.1, 0.2, 0.3, 0.4])           # per entry, row-major
    b = m.production(Y).output(P, [60.0, 60.0])
    b.input(F, q, price=1 + rates, taxes=[(G, rates)])           # per entry
    b.output(P, [1e-9, 1e-9], taxes=[(G[["g1", "g2"]], 0.0)])    # per owner
    spend = [2.0, 6.0, 12.0, 4.0]
    m.demand(HH).final(P, [[60.0 - 8.0, 60.0 - 16.0]]).endowment(F, [[60.0, 40.0]])
    d = m.demand(G, s=1.0)
    d.final(P["a"], np.array(spend) / 2).final(P["b"], np.array(spend) / 2)
    x = m.benchmark().x
    np.testing.assert_allclose(x[G.cols], rates * q.ravel(), rtol=1e-12)
