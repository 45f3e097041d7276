"""PATH 5.2's recorded figures (benchmarks/reference/) and the side-by-side benchmarks that
read them where GAMS cannot run: the files parse, every key is unique and has its run's
provenance, every problem of the benchmarks' default case lists has a row, and the
benchmarks run to the end with PATH unavailable, saying which source they used and
printing the recorded figures."""
import csv
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BENCH = ROOT / "benchmarks"
REF = BENCH / "reference"
SUITES = ("small", "thesis", "lcp", "cge", "links")
SCRIPTS = {"small": "bench_small.py", "thesis": "bench_thesis.py", "lcp": "bench_lcp.py",
           "cge": "bench_cge.py", "links": "bench_links.py"}
SMALL_LINE = ("# PATH: recorded 2026-11-26 at rev 2546e28 (benchmarks/reference/small.csv); "
              "GAMS cannot run: ")


def _bench(name):
    """A benchmark module as its scripts import it (benchmarks/ on sys.path)."""
    if str(BENCH) not in sys.path:
        sys.path.insert(0, str(BENCH))
    __import__(name)
    return sys.modules[name]


@pytest.fixture(scope="module")
def common():
    return _bench("_common")


def _meta(suite):
    return json.loads((REF / f"{suite}.json").read_text())


def _raw(suite):
    with open(REF / f"{suite}.csv", newline="") as fh:
        return list(csv.DictReader(fh))


def _no_gams_env():
    """An environment in which GAMS cannot run, whatever this machine has: GAMSPy's system
    directory points nowhere (the probe then finds no GAMS)."""
    env = dict(os.environ)
    env["GAMSPY_GAMS_SYSDIR"] = str(ROOT / "no-such-gams-system")
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return env


# --------------------------------------------------------------------------- the files
@pytest.mark.parametrize("suite", SUITES)
def test_reference_file_parses_with_unique_keys_and_each_rows_run(suite, common):
    meta = _meta(suite)
    raw = _raw(suite)
    key = list(meta["key"])
    assert meta["suite"] == suite and meta["file"] == f"{suite}.csv"
    assert SCRIPTS[suite] in meta["benchmark"]
    assert list(raw[0]) == key + list(meta["columns"])  # every column is described
    assert all(meta["columns"].values())
    assert len(raw) == meta["rows"] > 0
    conv = {"int": int, "float": float, "str": str}
    keys = [tuple(conv[meta["key"][f]](r[f]) for f in key) for r in raw]
    assert len(set(keys)) == len(keys), "a key appears twice"
    for rid, run in meta["runs"].items():
        assert re.fullmatch(r"\d{4}-\d\d-\d\d", run["date"]), rid
        assert run["date"] <= "2026-11-26"  # measured before the demo licence expired
        assert re.fullmatch(r"[0-9a-f]{7}", run["revision"]), rid
        assert SCRIPTS[suite] in run["command"], rid
        assert run["sources"] and all(s.startswith("benchmarks/results/")
                                      for s in run["sources"])
    assert {r["run"] for r in raw} <= set(meta["runs"])
    ref = common.PathReference(suite)
    assert len(ref.rows) == len(raw)
    for k, r in ref.rows.items():
        run = meta["runs"][r["run"]]
        assert r["path_source"] == f"recorded {run['date']} {run['revision']}"
        assert ref.get(**dict(zip(key, k))) == r
    for a in meta["absent"]:
        assert a["reason"] and ref.key(**a["key"]) not in ref.rows


@pytest.mark.parametrize("suite", ["small", "thesis", "lcp", "cge"])
def test_recorded_success_is_our_residual_verdict_and_times_are_measured(suite, common):
    """success is OUR test of PATH's point (natural residual <= 1e-6), not PATH's word."""
    ref = common.PathReference(suite)
    for k, r in ref.rows.items():
        assert r["success"] is (r["natural"] <= common.SUCCESS_TOL), k
        assert math.isfinite(r["time"]) and r["time"] > 0, k
        assert r["status"], k
        if "reported_success" in r:  # PATH's own verdict is its exit message's
            assert r["reported_success"] is (r["status"] == "solution found"), k
        if "major" in r:
            assert min(r["major"], r["minor"], r["crash"]) >= 0, k


def test_provenance_revisions_are_commits_of_this_repository():
    shallow = subprocess.run(["git", "rev-parse", "--is-shallow-repository"], cwd=ROOT,
                             capture_output=True, text=True)
    if shallow.returncode != 0 or shallow.stdout.strip() != "false":
        pytest.skip("not a full git clone")
    for suite in SUITES:
        meta = _meta(suite)
        revs = {r["revision"] for r in meta["runs"].values()}
        revs |= {r["source_commit"].split()[0] for r in meta["runs"].values()}
        revs.add(meta["built_from_revision"])
        for rev in revs:
            ok = subprocess.run(["git", "cat-file", "-e", f"{rev}^{{commit}}"], cwd=ROOT)
            assert ok.returncode == 0, f"{suite}: {rev} is not a commit"


def test_the_files_are_the_recorded_rows_unchanged():
    """build.py, from the result files at the source revision, writes exactly these files
    (no figure edited by hand)."""
    shallow = subprocess.run(["git", "rev-parse", "--is-shallow-repository"], cwd=ROOT,
                             capture_output=True, text=True)
    if shallow.returncode != 0 or shallow.stdout.strip() != "false":
        pytest.skip("not a full git clone")
    run = subprocess.run([sys.executable, str(REF / "build.py"), "--check"], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and "up to date" in run.stdout, run.stdout + run.stderr


def test_the_runs_that_measured_the_same_solve_agree():
    for suite in ("thesis", "lcp", "cge"):
        cc = _meta(suite)["cross_check"]
        assert cc["keys_measured_more_than_once"] > 0 and cc["disagreements"] == []


# --------------------------------------------------------------------------- coverage
def test_every_case_of_bench_small_by_default_has_a_path_row(common):
    bs = _bench("bench_small")
    ref = common.PathReference("small")
    cases = bs.cases_of(bs.parser().parse_args([]))
    assert len(cases) == 31
    for c in cases:
        k = ref.key(group=c.group, name=c.name, n=c.n)
        assert k in ref.rows or k in ref.absent, (c.group, c.name, c.n)
        row = bs.recorded_path(c, ref)
        if k in ref.absent:
            assert row is None
            continue
        assert row["time"] == ref.rows[k]["time"] and row["path_source"].startswith("recorded")
        assert set(row) <= set(bs.FIELDS)


def test_thesis_reference_covers_quick_the_30_instance_tables_and_the_tolerance_study(common):
    bt = _bench("bench_thesis")
    ref = common.PathReference("thesis")
    want = [(f, n, s, 1e-6) for f in (1, 2) for n in (10, 20, 50, 100, 200, 500)
            for s in range(30)]
    want += [(f, n, s, t) for f, n, s in bt.TOLERANCE_INSTANCES + bt.TOLERANCE_INSTANCES_QUICK
             for t in bt.TOLERANCES]
    for f, n, s, t in want:
        assert ref.get(family=f, n=n, seed=s, tol=t) is not None, (f, n, s, t)
    assert ref.get(family=1, n=10, seed=30, tol=1e-6) is None  # seeds 30-99: not recorded
    rec = bt.recorded_path(ref, 2, 50, 0, 1e-6)
    assert set(bt.FIELDS) <= set(rec) and rec["solver"] == "PATH"
    assert rec["path_source"] == "recorded 2026-11-22 c6c1c37"


def test_lcp_reference_covers_part_b_at_the_instances_true_sizes(common):
    bl = _bench("bench_lcp")
    ref = common.PathReference("lcp")
    for n in (100, 300, 1000):
        for kind, bounds in (("grid", "ncp"), ("grid", "mixed"), ("banded", "ncp"),
                             ("banded", "mixed"), ("obstacle", "lower")):
            g = bl._instance(kind, n, 0, bounds)
            n_true = g.lcp[1].size  # the benchmark's row n
            for config in bl.CONFIGS:
                rec = bl.recorded_path(ref, kind, bounds, n_true, 0, config)
                assert rec is not None, (kind, bounds, n_true, config)
                assert rec["n"] == n_true and set(rec) <= set(bl.FIELDS)
    assert bl.recorded_path(ref, "obstacle", "lower", 300, 0, "default") is None  # n = 289


def test_cge_reference_is_the_ramsey_model_bench_cge_builds(common):
    from compass_sparse.generators.cge import ramsey_cge

    bc = _bench("bench_cge")
    ref = common.PathReference("cge")
    for T in (40, 110):
        prob = ramsey_cge(periods=T, sectors=1).with_shock(capital_tax=0.25).problem
        for tax in (-0.1, 0.25):
            r = ref.get(T=T, tax=tax)
            assert r is not None and r["n"] == prob.n
            row = bc._recorded_path_row(T, tax, prob, r)
            assert row["time"] == r["time"] and row["K5_change"] == r["K5_change"]
            assert row["max_rel_diff"] == ""  # against an old point: not carried over
            assert set(row) <= set(bc.PATH_FIELDS)
    other = ramsey_cge(periods=11, sectors=1).with_shock(capital_tax=0.25).problem
    bad = bc._recorded_path_row(40, 0.25, other, ref.get(T=40, tax=0.25))
    assert bad["status"] == "not recorded" and "n = 363" in bad["error"]


def test_links_reference_has_every_model_of_the_gamspy_part(common):
    ref = common.PathReference("links")
    sizes = _bench("bench_links").GAMS_SIZES
    for model, by_n in sizes.items():
        for n_target, args in by_n.items():
            r = ref.get(model=model, n_target=n_target)
            assert r is not None and r["size_arg"] == args[0]


# --------------------------------------------------------------------------- the source
def test_path_source_follows_the_probe_and_the_option(common, monkeypatch):
    monkeypatch.setattr(common, "why_path_cannot_run", lambda: "GAMS cannot run: test")
    src = common.choose_path_source("small")
    assert src.recorded and src.why == "GAMS cannot run: test"
    assert src.line() == SMALL_LINE + "test; ratios against PATH compare with a run of another day"
    with pytest.raises(SystemExit, match="GAMS cannot run: test"):
        common.choose_path_source("small", "live")
    assert common.choose_path_source("small", no_path=True).mode == "none"
    monkeypatch.setattr(common, "why_path_cannot_run", lambda: None)
    assert common.choose_path_source("small").live
    asked = common.choose_path_source("thesis", "recorded")
    assert asked.recorded and "--path recorded asked" in asked.line()
    ref = asked.reference  # the line names only the runs the planned rows come from
    keys = [ref.key(family=1, n=500, seed=0, tol=1e-6)]
    assert "2026-11-23 at rev ced30d6 (benchmarks/reference/thesis.csv)" in asked.line(keys)
    assert "c6c1c37" not in asked.line(keys)


# --------------------------------------------------------------------------- the runs
def test_bench_small_runs_to_the_end_with_path_unavailable_and_prints_the_record(tmp_path):
    """The default source where GAMS cannot run: PATH's recorded rows, said in the first
    lines, marked in the CSV, and the ratios taken against them; a problem the reference
    lacks (thesis n = 20) gets '–'."""
    out = tmp_path / "small.csv"
    run = subprocess.run(
        [sys.executable, str(BENCH / "bench_small.py"), "--groups", "known", "thesis",
         "--thesis-n", "10", "20", "--families", "1", "--seeds", "1", "--repeats", "1",
         "--no-import-time", "--out", str(out)],
        cwd=ROOT, env=_no_gams_env(), capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    lines = run.stdout.splitlines()
    source = [ln for ln in lines if ln.startswith("# PATH:")]
    assert len(source) == 1 and source[0].startswith(SMALL_LINE), source
    assert lines.index(source[0]) <= 3  # at the start
    assert any("fam1_n20_s1" in ln and "– (not in the reference)" in ln for ln in lines)
    sys.path.insert(0, str(BENCH))
    from _common import PathReference, read_csv

    ref = PathReference("small")
    rows = read_csv(out)
    ours = {r["name"]: r for r in rows if r["solver"] == "compass_sparse"}
    path = {r["name"]: r for r in rows if r["solver"] == "PATH"}
    assert len(ours) == 12 and "fam1_n20_s1" in ours and "fam1_n20_s1" not in path
    assert len(path) == 11
    for name, p in path.items():
        rec = ref.get(group=p["group"], name=name, n=p["n"])
        assert p["path_source"] == "recorded 2026-11-26 2546e28"
        assert p["time"] == rec["time"] and p["success"] is rec["success"]
        assert p["status"] == rec["status"] and p["natural"] == rec["natural"]
    assert path["billups"]["success"] is False  # PATH's recorded failure, kept
    assert all(r["path_source"] == "" for r in ours.values())
    # the summary: marked columns, and cournot2's ratio is our CPU time over PATH's record
    head = next(ln for ln in lines if ln.startswith("| group | problem |"))
    assert "PATH time (recorded)" in head and "ratio vs recorded PATH" in head
    row = next(ln for ln in lines if ln.startswith("| known | cournot2 |"))
    ratio = float(row.strip("|").split("|")[-1])
    want = ours["cournot2"]["cpu"] / ref.get(group="known", name="cournot2", n=2)["time"]
    assert ratio == pytest.approx(want, abs=0.006)
    assert any("compares our time today with PATH's time on another day" in ln for ln in lines)


def test_bench_thesis_takes_recorded_rows_and_leaves_out_what_is_not_recorded(tmp_path):
    out = tmp_path / "thesis.csv"
    run = subprocess.run(
        [sys.executable, str(BENCH / "bench_thesis.py"), "--instances", "2", "--seed0", "29",
         "--sizes", "10", "--families", "1", "--repeats", "1", "--out", str(out)],
        cwd=ROOT, env=_no_gams_env(), capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    assert ("# PATH: recorded 2026-11-22 at rev c6c1c37 (benchmarks/reference/thesis.csv); "
            "GAMS cannot run: ") in run.stdout
    assert "seed  30 PATH            – (not in the reference)" in run.stdout
    sys.path.insert(0, str(BENCH))
    from _common import PathReference, read_csv

    rows = read_csv(out)
    path = [r for r in rows if r["solver"] == "PATH"]
    assert [r["seed"] for r in path] == [29]
    rec = PathReference("thesis").get(family=1, n=10, seed=29, tol=1e-6)
    for f in ("time", "major", "minor", "crash", "natural", "status", "success"):
        assert path[0][f] == rec[f], f
    assert path[0]["path_source"] == "recorded 2026-11-22 c6c1c37"
    assert "| 1 / PATH (recorded) |" in run.stdout  # the cell counts seed 29 only: K=1
    assert "(K=1)" in run.stdout


def test_bench_links_prints_paths_recorded_column_without_gams():
    run = subprocess.run([sys.executable, str(BENCH / "bench_links.py"), "--parts", "gamspy"],
                         cwd=ROOT, env=_no_gams_env(), capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    assert ("# PATH: recorded 2026-11-23 at rev 90c43c7 (benchmarks/reference/links.csv)"
            in run.stdout)
    assert "solve PATH [s] (recorded)" in run.stdout
    for model, n, t in (("cournot", 100, "0.08"), ("cournot", 995, "0.15"),
                        ("spatial", 101, "0.15"), ("spatial", 997, "0.13")):
        assert f"| {model} | {n} | – | – | – | – | – | {t} | – |" in run.stdout


def test_static_cge_gamspy_raises_the_licence_error_where_gams_refuses(monkeypatch):
    """The GAMSPy model of bench_small's static CGE cases, asked for a live PATH run where
    GAMS refuses its licence: the package's GamsLicenseError with GAMS' lines, before any
    GAMSPy container is made (GAMSPy's own message would only say 'bad state')."""
    import datetime

    from compass_sparse.generators.cge import size_for, static_cge

    import compass_sparse.interfaces.gams_state as gs
    from compass_sparse.exceptions import GamsLicenseError

    refused = gs.GamsState("licence-refused", "time-limited licence expired 2026-11-26",
                           licence_lines=("*** Time-limited license expired 1 days ago",),
                           expired_on=datetime.date(2026, 11, 26))
    monkeypatch.setattr(gs, "_STATE", refused)
    static = _bench("static_cge_gamspy")
    monkeypatch.setattr(static, "static_container",
                        lambda model: pytest.fail("a GAMSPy container was built"))
    model = static_cge(**size_for(90)).with_shock(output_tax=0.25)
    with pytest.raises(GamsLicenseError, match="expired 2026-11-26") as err:
        static.solve_static_with_path(model)
    assert "Time-limited license expired 1 days ago" in str(err.value)
