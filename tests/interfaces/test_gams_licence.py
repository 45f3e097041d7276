"""GAMS' licence: the probe of GAMS' state, and GamsLicenseError where GAMS refuses.

These tests run everywhere (GAMSPy installed or not, licence valid or not): a fake GAMS
system directory holds a script named ``gams`` that answers the probe's job as GAMS does
(the licence lines are GAMS 54's, as printed on 2026-11-27 under the expired demo licence).
The last test runs the real GAMS when its licence is refused on this machine.
"""
import datetime as dt
import os
import stat
import sys

import pytest

import compass_sparse.interfaces.gams_state as gs
from compass_sparse.exceptions import CompassError, GamsLicenseError

pytestmark = pytest.mark.skipif(sys.platform.startswith("win"),
                                reason="the fake GAMS is a POSIX shell script")

EXPIRED = """--- Job probe.gms Start 11/27/26 21:33:07 54.6.1 20a39885 LEX-LEG x86 64bit/Linux
*** Time-limited license expired 3 days ago
*** Status: Terminated due to a licensing error
***         License file: /opt/gams/gamslice.txt
***         Inspect listing file for more information.
--- Job probe.gms Stop 11/27/26 21:33:07 elapsed 0:00:00.002"""
INVALID = """*** Error: The installed license /opt/gams/gamslice.txt is invalid.
           *** License with wrong platform code."""
FATAL = ("Error while getting the return code from GAMS backend. This means that GAMS is in "
         "a bad state. Try to backtrack for previous errors.")
SIZE = ("*** The model exceeds the demo license limits for nonlinear models of more than 1000 "
        "rows or columns\n*** Status: Terminated due to a licensing error")


def fake_gams(folder, log, code, listing="probe          =        1.000"):
    """A GAMS system directory whose ``gams`` prints ``log``, writes a listing, exits ``code``."""
    folder.mkdir(exist_ok=True)
    (folder / "log.txt").write_text(log + "\n")
    (folder / "lst.txt").write_text(listing + "\n")
    exe = folder / "gams"
    exe.write_text(f'#!/bin/sh\ncat "{folder}/log.txt"\ncp "{folder}/lst.txt" probe.lst\n'
                   f"exit {code}\n")
    exe.chmod(exe.stat().st_mode | stat.S_IXUSR)
    return str(folder)


@pytest.fixture
def gams_at(monkeypatch, tmp_path):
    """Point GAMSPy's system directory at a fake GAMS; the process cache starts empty and is
    restored afterwards."""
    monkeypatch.setattr(gs, "_STATE", None)
    monkeypatch.delenv("GAMSPY_LICENSE_PATH", raising=False)

    def use(log, code, **kw):
        d = fake_gams(tmp_path / "gams", log, code, **kw)
        monkeypatch.setenv("GAMSPY_GAMS_SYSDIR", d)
        return d
    return use


class FatalError(Exception):
    """Stands for gamspy.exceptions.FatalError: what GAMSPy raises when GAMS stops a job."""


def test_probe_reads_an_expired_licence_and_its_date(gams_at):
    gams_at(EXPIRED, 7)
    st = gs.gams_state()
    assert st.condition == "licence-refused" and not st.runs
    assert st.expired_on == dt.date.today() - dt.timedelta(days=3)
    assert st.reason == f"time-limited licence expired {st.expired_on.isoformat()}"
    assert st.licence_lines[:2] == ("*** Time-limited license expired 3 days ago",
                                    "*** Status: Terminated due to a licensing error")
    assert gs.gams_state() is st  # cached per process


def test_probe_reads_an_invalid_licence(gams_at):
    gams_at(INVALID, 7)
    st = gs.gams_state()
    assert st.condition == "licence-refused" and st.expired_on is None
    assert "is invalid" in st.reason
    assert st.licence_lines == ("*** Error: The installed license /opt/gams/gamslice.txt is "
                                "invalid.", "*** License with wrong platform code.")


def test_probe_sees_gams_run(gams_at):
    gams_at("--- Job probe.gms Stop 11/27/26 21:33:07 elapsed 0:00:00.002", 0)
    st = gs.gams_state()
    assert st.runs and st.condition == "runs"


def test_probe_without_gams_says_not_installed(monkeypatch, tmp_path):
    monkeypatch.setenv("GAMSPY_GAMS_SYSDIR", str(tmp_path))  # a folder with no GAMS in it
    st = gs.probe_gams()
    assert st.condition == "not-installed" and "not installed" in st.reason


def test_probe_reports_a_gams_that_fails_for_another_reason(gams_at):
    gams_at("*** Error: could not create process directory", 2, listing="")
    st = gs.gams_state()
    assert st.condition == "failed" and "return code 2" in st.reason


def test_expired_licence_makes_solve_gamspy_raise_gams_licence_error_not_fatal_error(gams_at):
    """solve_gamspy on any model, GAMS refusing its licence: GamsLicenseError naming the
    expiry, quoting GAMS and saying what to do; the probe answers before GAMSPy is touched."""
    from compass_sparse.interfaces.gamspy import gamspy_available, solve_gamspy
    from compass_sparse.interfaces.path_gamspy import PathLicenseError, PathSession
    from compass_sparse.interfaces.path_gamspy import path_available

    gams_at(EXPIRED, 7)
    with pytest.raises(GamsLicenseError) as info:
        solve_gamspy(object(), object())
    err = info.value
    assert isinstance(err, CompassError)
    assert err.kind == "expired"
    day = (dt.date.today() - dt.timedelta(days=3)).isoformat()
    assert f"time-limited licence expired {day}" in str(err)
    assert "*** Time-limited license expired 3 days ago" in str(err)
    assert "gamspy install license" in str(err)
    with pytest.raises(PathLicenseError):  # the PATH runner, by its old name too
        PathSession(3)
    assert not path_available() and not gamspy_available()


def test_fatal_error_of_a_licence_that_expires_mid_process_becomes_gams_licence_error(
        gams_at, tmp_path):
    """GAMS ran when first probed; later a job fails with GAMSPy's 'bad state' message (no
    word of a licence): the refusal is found by probing again, the FatalError is chained."""
    gams_at("ok", 0)
    assert gs.gams_state().runs
    gams_at(EXPIRED, 7)  # the licence expires
    with pytest.raises(GamsLicenseError) as info:
        with gs.gams_refusals("run PATH"):
            raise FatalError(FATAL)
    assert isinstance(info.value.__cause__, FatalError)
    assert "GAMS cannot run PATH: time-limited licence expired" in str(info.value)
    assert "Terminated due to a licensing error" in str(info.value)


def test_model_above_the_licence_size_is_a_size_refusal_with_gams_lines(gams_at):
    gams_at("ok", 0)
    with pytest.raises(GamsLicenseError) as info:
        with gs.gams_refusals("generate model big", log=lambda: SIZE):
            raise FatalError(FATAL)
    assert info.value.kind == "size"
    assert "1000 rows and columns" in str(info.value)
    assert "exceeds the demo license limits" in str(info.value)


def test_errors_that_are_not_refusals_pass_unchanged(gams_at):
    gams_at("ok", 0)
    with pytest.raises(ZeroDivisionError):
        with gs.gams_refusals():
            1 / 0
    assert gs.refusal_from(ValueError("domain violation in x"), "") is None


def test_licence_path_follows_gamspy(monkeypatch, tmp_path):
    monkeypatch.setenv("GAMSPY_LICENSE_PATH", str(tmp_path / "lic.txt"))
    assert gs._licence_path(str(tmp_path)) == str(tmp_path / "lic.txt")
    monkeypatch.delenv("GAMSPY_LICENSE_PATH")
    monkeypatch.setenv("HOME", str(tmp_path))
    assert gs._licence_path(str(tmp_path)) is None  # GAMS' own default licence
    user = tmp_path / ".local" / "share" / "GAMSPy"
    user.mkdir(parents=True)
    (user / "gamspy_license.txt").write_text("x")
    if sys.platform.startswith("linux"):
        assert gs._licence_path(str(tmp_path)) == str(user / "gamspy_license.txt")


def test_real_gams_with_a_refused_licence_raises_gams_licence_error():
    """This machine's GAMS, where its licence is refused: the PATH runner and the example
    models raise GamsLicenseError with GAMS' own lines."""
    st = gs.probe_gams()
    if st.condition != "licence-refused":
        pytest.skip(f"GAMS here: {st.reason} (the refusal is simulated in the tests above)")
    from compass_sparse.examples import cournot
    from compass_sparse.interfaces.path_gamspy import PathSession

    for build in (lambda: PathSession(2), lambda: cournot.gamspy_model(cournot.data(2))):
        with pytest.raises(GamsLicenseError) as info:
            build()
        assert st.licence_lines[0] in str(info.value)
        assert st.reason in str(info.value)
    assert os.path.isdir(st.sysdir)
