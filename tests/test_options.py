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
