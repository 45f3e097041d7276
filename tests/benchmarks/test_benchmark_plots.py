"""benchmarks/plots.py draws its four figures from the checked-in benchmark rows."""
import importlib.util
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]


def _plots():
    spec = importlib.util.spec_from_file_location("bench_plots", ROOT / "benchmarks" / "plots.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_benchmark_plots_are_drawn_from_the_recorded_rows(tmp_path, capsys):
    pytest.importorskip("matplotlib", reason="the plot extra (matplotlib) is not installed")
    plots = _plots()
    plots.main(["--outdir", str(tmp_path)])
    for _, png in plots.FIGURES.values():
        assert (tmp_path / png).stat().st_size > 10_000, png
        assert (ROOT / "benchmarks" / png).exists(), f"{png} is not checked in"


def test_paired_costs_keep_only_instances_both_solvers_ran_and_mark_failures():
    plots = _plots()
    rows = [
        {"n": "10", "seed": "0", "solver": "compass_sparse", "success": "True", "time": "0.5"},
        {"n": "10", "seed": "0", "solver": "PATH", "success": "False", "time": "0.1"},
        {"n": "10", "seed": "1", "solver": "compass_sparse", "success": "True", "time": "0.2"},
    ]
    costs = plots._paired_costs(rows, lambda r: (r["n"], r["seed"]))
    assert costs.shape == (1, 2)
    assert costs[0, 0] == 0.5 and np.isinf(costs[0, 1])
