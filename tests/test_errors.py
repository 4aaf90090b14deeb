"""hystid's exceptions and warnings: defined once, in hystid.errors, and still found where users
imported them from."""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import warnings

import pytest

import hystid
from hystid import errors

#: Where each class was importable before it moved to hystid.errors.
OLD_HOMES = [
    ("hystid.records", "RecordError"),
    ("hystid.records.record", "RecordError"),
    ("hystid.modelfile", "ModelFileError"),
    ("hystid.document", "ModelFileError"),
    ("hystid.safeio", "OutputError"),
    ("hystid.options", "OptionError"),
    ("hystid.fleet", "FleetError"),
    ("hystid.diagnose", "DiagnosisError"),
    ("hystid.diagnose.diagnosis", "DiagnosisError"),
    ("hystid.diagnose.rounds", "DiagnosisError"),
    ("hystid.identify.prepare", "IdentificationDataError"),
    ("hystid.operating", "AdmissibilityWarning"),
    ("hystid.compensate", "CompensationWarning"),
    ("hystid.compensate.placed", "CompensationWarning"),
    ("hystid.cli", "CommandError"),
    ("hystid.cli.support", "CommandError"),
]


@pytest.mark.parametrize(("module", "name"), OLD_HOMES)
def test_each_class_is_still_found_where_it_was(module, name):
    assert getattr(importlib.import_module(module), name) is getattr(errors, name)


def test_the_bases_callers_catch_are_kept():
    for name in ("RecordError", "ModelFileError", "OutputError", "OptionError", "FleetError",
                 "DiagnosisError", "IdentificationDataError"):
        assert issubclass(getattr(errors, name), ValueError), name
    assert not issubclass(errors.CommandError, ValueError)  # a library ValueError is no refusal
    assert issubclass(errors.AdmissibilityWarning, RuntimeWarning)
    assert issubclass(errors.CompensationWarning, UserWarning)
    assert set(errors.__all__) == {n for n, c in vars(errors).items()
                                   if inspect.isclass(c) and issubclass(c, BaseException)}


def test_record_error_still_names_where_the_problem_is():
    err = errors.RecordError("value 'nan' is not finite", file="rec.csv", line=17, column="y")
    assert str(err) == "rec.csv, line 17, column 'y': value 'nan' is not finite"
    assert (err.file, err.line, err.column, err.array, err.index) == ("rec.csv", 17, "y", None,
                                                                     None)


def test_no_other_module_defines_an_exception_or_a_warning():
    found = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for info in pkgutil.walk_packages(hystid.__path__, "hystid."):
            if info.name.endswith("__main__"):
                continue  # running it is the command line itself
            module = importlib.import_module(info.name)
            for name, obj in vars(module).items():
                if (inspect.isclass(obj) and issubclass(obj, BaseException)
                        and obj.__module__ == info.name and info.name != "hystid.errors"):
                    found.append(f"{info.name}.{name}")
    assert not found, found
