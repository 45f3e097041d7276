"""The modelling-language links stay optional: the package and its examples import without
Pyomo, CasADi or GAMSPy, and the link modules import (and report unavailability) without them."""
import subprocess
import sys

BLOCK = "import sys\nfor m in ('pyomo', 'casadi', 'gamspy', 'gams'):\n    sys.modules[m] = None\n"


def run(code):
    out = subprocess.run([sys.executable, "-c", BLOCK + code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    return out.stdout


def test_package_and_examples_import_without_the_modelling_languages():
    run("import compass_sparse, compass_sparse.examples.cournot, compass_sparse.examples.cge\n"
        "from compass_sparse.examples import spatial\n"
        "kw = spatial.callables(spatial.data(5))\n"
        "r = compass_sparse.solve_mcp(**kw)\n"
        "assert r.success\n")


def test_link_modules_import_and_report_unavailable_without_their_language():
    out = run("import compass_sparse.interfaces.pyomo as p, compass_sparse.interfaces.gamspy as g\n"
              "print(p.pyomo_available(), g.gamspy_available())\n")
    assert out.split() == ["False", "False"]
