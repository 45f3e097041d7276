"""The GAMSPy formulation of the static CGE model (benchmarks/static_cge_gamspy.py) is the
generator's MCP: PATH's solution of it zeroes the generator's F and is our solution."""
import sys
from pathlib import Path

import numpy as np
import pytest

from compass_sparse import solve_mcp
from compass_sparse.generators.cge import static_cge
from compass_sparse.merit import natural_residual

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from static_cge_gamspy import solve_static_with_path  # noqa: E402


@pytest.mark.gams
@pytest.mark.parametrize("regions, shock", [
    (1, dict(output_tax=0.25)),
    (2, dict(tariff=0.25)),
    (3, dict(tariff=(1, 0.4), endowment=1.1)),
])
def test_path_solution_of_gamspy_static_model_solves_generator_model(regions, shock):
    model = static_cge(regions=regions, sectors=4, factors=2, households=2, seed=regions)
    shocked = model.with_shock(**shock)
    out = solve_static_with_path(shocked)
    assert out["status"] == "solution found", out["log"][-2000:]
    assert out["size"][0] == shocked.n - 1  # GAMS drops the fixed numeraire income
    x = out["x"]
    assert natural_residual(x, shocked.F(x), shocked.lb, shocked.ub) <= 1e-6
    # the shock moves the point: the two solves are not agreeing at the start
    assert np.max(np.abs(x - shocked.problem.x0)) > 1e-3
    ours = solve_mcp(shocked.problem)
    np.testing.assert_allclose(x, ours.x, rtol=1e-5, atol=1e-6)


def test_gamspy_static_model_refuses_cobb_douglas_nests():
    model = static_cge(regions=1, sectors=3, sigma_va=1.0).with_shock(output_tax=0.1)
    with pytest.raises(NotImplementedError, match="general CES"):
        solve_static_with_path(model)
