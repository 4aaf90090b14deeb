"""Every exception and warning hystid raises, in one place.

Each is a subclass of the built-in type a caller would catch anyway (most are
:class:`ValueError`, the warnings a :class:`RuntimeWarning` or :class:`UserWarning`), and each
message names what is wrong and what was expected. The modules that raise them also hand them
on under their old names (``from hystid.records import RecordError`` still works).

* :class:`RecordError` (ValueError) -- a record or a record file, :mod:`hystid.records`;
* :class:`ModelFileError` (ValueError) -- a model file, :mod:`hystid.modelfile`;
* :class:`OutputError` (ValueError) -- an output path, :mod:`hystid.safeio`;
* :class:`IdentificationDataError` (ValueError) -- a record that cannot identify a stage,
  :mod:`hystid.identify`;
* :class:`DiagnosisError` (ValueError) -- a diagnosis' input, :mod:`hystid.diagnose`;
* :class:`FleetError` (ValueError) -- a fleet's input, :mod:`hystid.fleet`;
* :class:`OptionError` (ValueError) -- a command-line value, :mod:`hystid.options`;
* :class:`CommandError` (Exception) -- an input the ``hystid`` command refuses,
  :mod:`hystid.cli`;
* :class:`Cancelled` (BaseException) -- a fit started ahead of a decision that no longer needs
  it, stopped inside :func:`hystid.threads.cancellable` (it never reaches a caller);
* :class:`AdmissibilityWarning` (RuntimeWarning) -- a model used outside what it was
  identified for;
* :class:`CompensationWarning` (UserWarning) -- a compensator that had to approximate,
  :func:`hystid.compensate.compensate`.
"""

from __future__ import annotations

import os

__all__ = ["AdmissibilityWarning", "Cancelled", "CommandError", "CompensationWarning",
           "DiagnosisError", "FleetError", "IdentificationDataError", "ModelFileError",
           "OptionError", "OutputError", "RecordError"]


# --------------------------------------------------------------------------- data
class RecordError(ValueError):
    """A record or a record file is invalid.

    Raised by :func:`hystid.records.load_record`, :class:`hystid.records.Record` and
    :meth:`~hystid.records.Record.save` on a file that cannot be read, a signal that is not
    finite, a time vector that is not uniform, mismatched lengths or a hostile file.
    The message starts with the location of the problem (file, line, column, or array and index,
    whichever are known) followed by what is wrong and what was expected, for example
    ``rec.csv, line 17, column 'y': value 'nan' is not finite (expected a finite number)``.

    Parameters
    ----------
    message : str
        What is wrong and what was expected.
    file : str or os.PathLike, optional
        The file, as the user named it.
    line : int, optional
        1-based line number, counting comment and header lines.
    column : str, optional
        Column name (CSV files).
    array : str, optional
        Array, variable or dataset name (NumPy, MATLAB and HDF5 files).
    kind : str, optional
        What ``array`` is called in the message: ``"array"`` (default), ``"variable"``, ...
    index : int, optional
        0-based sample index in ``array``.

    Attributes
    ----------
    file, line, column, array, index
        The location given at construction (``None`` when unknown).
    """

    def __init__(
        self,
        message: str,
        *,
        file: str | os.PathLike[str] | None = None,
        line: int | None = None,
        column: str | None = None,
        array: str | None = None,
        kind: str = "array",
        index: int | None = None,
    ) -> None:
        self.file = None if file is None else os.fspath(file)
        self.line = line
        self.column = column
        self.array = array
        self.index = index
        parts = []
        if self.file is not None:
            parts.append(self.file)
        if line is not None:
            parts.append(f"line {line}")
        if column is not None:
            parts.append(f"column {column!r}")
        if array is not None:
            parts.append(f"{kind} {array!r}")
        if index is not None:
            parts.append(f"index {index}")
        super().__init__(f"{', '.join(parts)}: {message}" if parts else message)


class ModelFileError(ValueError):
    """A model file cannot be read or written; the message names the file and the entry.

    Raised by :func:`hystid.load_model` on a file that is not a hystid model file (not JSON,
    another format or version, an entry missing, of the wrong type or out of range) and by
    :func:`hystid.save_model` on a model it cannot write.
    """


class OutputError(ValueError):
    """An output path that must not be written (the message names the option and the path).

    Raised by the checks of :mod:`hystid.safeio` before any work (an output that is one of the
    inputs, an existing file without ``force``, a symbolic link, a folder that cannot be
    written) and by its atomic writers when a file appeared at the destination meanwhile, or
    another hystid run holds the folder's lock.
    """


# --------------------------------------------------------------------------- the work
class IdentificationDataError(ValueError):
    """The record cannot identify a stage; the message names the record and the reason.

    Raised when an identification prepares its record (:func:`hystid.identify.prepare.prepare`,
    through :func:`~hystid.identify.prepare.check_excitation`): the input is constant or a
    single step, or the output is the input read twice.
    """


class DiagnosisError(ValueError):
    """Bad input for a diagnosis (too short, not excited, mismatched sampling rates...).

    Raised by :func:`hystid.diagnose.diagnose` before its work on settings out of range,
    records too short to split or of another sampling rate, a model that is not a Duhem
    sandwich, and named candidate effects the records cannot show; and when the nominal
    model's simulation diverges on the records.
    """


class FleetError(ValueError):
    """Bad fleet input (no records, a malformed table, a results file that is not ours).

    Raised by :func:`hystid.fleet.find_jobs` and :func:`hystid.fleet.run_fleet` before any
    record is submitted: also when the scheduler cannot be reached, or another run holds the
    output folder.
    """


# --------------------------------------------------------------------------- the command line
class OptionError(ValueError):
    """A command-line option has a value hystid cannot use; the message names the option.

    Raised by :func:`hystid.options.parse_crop`, :func:`hystid.options.crop` and
    :func:`hystid.options.parse_structure`.
    """


class CommandError(Exception):
    """A user-facing error of the ``hystid`` command: printed without a traceback, status 2.

    Raised by the steps of a command (:mod:`hystid.cli`) on an input it refuses, before its
    work where it can; the command's runner prints ``hystid COMMAND: error: MESSAGE`` and
    returns :data:`hystid.cli.support.EXIT_BAD_INPUT`.
    """


class Cancelled(BaseException):
    """Raised inside a fit started by :func:`hystid.threads.cancellable` once its event is set
    (:func:`hystid.threads.check_cancelled`), and caught there: the fit returns None. A
    ``BaseException``, so that no ``except Exception`` on the way swallows it.
    """


# --------------------------------------------------------------------------- warnings
class AdmissibilityWarning(RuntimeWarning):
    """A model is used outside what it was identified for (input envelope or condition 8).

    Warned (through :func:`hystid.operating.warn_admissibility`) by the ``simulate`` of a
    placed model -- :class:`~hystid.model.DuhemSandwich`, :class:`~hystid.pi.PISandwich`, a
    diagnosed model -- on an input that leaves its :class:`~hystid.operating.Envelope` or on
    which the Duhem condition (8) fails, and by :func:`hystid.compensate.compensate` where the
    command leaves the envelope, saturates or an inverse step is not exact.
    """


class CompensationWarning(UserWarning):
    """The compensator had to approximate (non-minimum-phase L2, pre-actuation cut short).

    Warned by :func:`hystid.compensate.compensate`; the same notes are in its result's
    ``warnings``.
    """
