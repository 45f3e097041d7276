"""Options (compass_sparse.options): validation, dictionaries, every option read somewhere."""

import pytest

import compass_sparse as cs


def test_options_validation_and_dict():
    o = cs.Options.from_dict({"convergence_tolerance": 1e-8, "crash_method": "none"})
    assert o.convergence_tolerance == 1e-8 and o.crash_method == "none"
    with pytest.raises(cs.OptionError, match="did you mean 'convergence_tolerance'"):
        cs.Options.from_dict({"convergence_tolerence": 1e-8})
    with pytest.raises(cs.OptionError, match="must be > 0"):
        cs.Options(convergence_tolerance=0.0)
    with pytest.raises(cs.OptionError, match="expected one of"):
        cs.Options(crash_method="newton")
    with pytest.raises(cs.OptionError, match="integer"):
        cs.Options(major_iteration_limit=2.5)
    with pytest.raises(cs.OptionError):
        o.replace(no_such_option=1)
    assert "nms_memory_size" in cs.Options.describe()


def test_every_option_is_read_somewhere():
    """An option that no code reads is a promise the solver does not keep."""
    import dataclasses
    import pathlib
    import re

    root = pathlib.Path(cs.__file__).parent
    src = "\n".join(p.read_text() for p in root.rglob("*.py")
                    if p.name != "_options_base.py")
    unread = [f.name for f in dataclasses.fields(cs.Options)
              if not re.search(r"\.\s*" + f.name + r"\b", src)]
    assert unread == []


def test_options_from_equal_dicts_shared_but_true_and_one_stay_apart():
    from compass_sparse import Options
    from compass_sparse.exceptions import OptionError

    a = Options.coerce({"verbosity": 1, "time_limit": 5.0})
    assert Options.coerce({"time_limit": 5.0, "verbosity": 1}) is a
    assert Options.coerce(None) is Options.coerce({})
    with pytest.raises(OptionError):
        Options.coerce({"verbosity": True})  # equal to 1, but not an integer option value
    with pytest.raises(OptionError):
        Options.coerce({"time_limit": float("nan")})
    assert Options.coerce({"time_limit": float("inf")}).time_limit == float("inf")


def test_options_replace_shares_equal_copies_and_still_validates():
    """Restarts replace fields of the same options: the copy is built and validated once
    and shared (frozen), equal to a fresh dataclasses.replace; values that differ only in
    type (True and 1) give different copies, and invalid values still raise."""
    import dataclasses

    from compass_sparse import Options
    from compass_sparse.exceptions import OptionError

    base = Options.coerce({"time_limit": 7.0})
    a = base.replace(crash_method="none", nms_memory_size=2)
    assert base.replace(nms_memory_size=2, crash_method="none") is a
    assert a == dataclasses.replace(base, crash_method="none", nms_memory_size=2)
    assert a.time_limit == 7.0 and a.crash_method == "none" and base.crash_method != "none"
    assert Options.coerce({"time_limit": 8.0}).replace(crash_method="none") is not a
    with pytest.raises(OptionError):
        base.replace(nms_memory_size=True)   # equal to 1, but not an integer
    with pytest.raises(OptionError):
        base.replace(no_such_option=1)
    with pytest.raises(OptionError):
        base.replace(time_limit=float("nan"))

