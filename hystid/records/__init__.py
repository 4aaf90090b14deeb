"""Input/output records of a positioning stage and their loaders.

A :class:`Record` holds one experiment: the input ``u`` (typically the amplifier voltage), the
output ``y`` (typically the measured displacement), both sampled uniformly at ``fs`` Hz.

:func:`load_record` reads a record from CSV (``.csv``, ``.txt``, ``.tsv``), NumPy (``.npz``), MATLAB
(``.mat``) or HDF5 (``.h5``, ``.hdf5``, optionally ``file.h5:group/path``) files, and
:meth:`Record.save` writes the same formats. Every problem with the input data raises a
:class:`RecordError` whose message names the file, the line and the column (or the array and the
index) and says what was expected.

Time columns
------------
When a file carries a time vector ``t`` instead of (or besides) a sampling rate, ``fs`` is derived
from it. ``t`` must be strictly increasing and uniform: every step must be within
:data:`T_UNIFORM_RTOL` (0.1 %) of the median step. The tolerance is that loose on purpose: measured
files print ``t`` with about nine significant digits and their acquisition clock jitters (the
5 kHz piezo record steps between 0.19998 ms and 0.20002 ms, 1.5e-4 relative), while a genuinely
irregular sample (for example one sample 10 % late) is still rejected. Since single steps are that
noisy, ``fs`` is taken from the whole span, ``(n - 1) / (t[-1] - t[0])``, rather than from one
step. A sampling rate stated beside ``t`` (the ``fs=`` argument, or the comment line written by
:meth:`Record.save`) must agree with it within :data:`FS_RTOL`; the stated value is then used.
The time origin is not kept: :attr:`Record.t` always starts at 0.

Hostile files
-------------
A record file is read from its own bytes only, and never decodes to much more than it holds:

* HDF5 external links, datasets stored in external files and virtual datasets are refused;
* the declared size of every array (npz member, MATLAB variable -- read from the variable
  headers without inflating the data -- or HDF5 dataset) may exceed the file's size at most
  :data:`MAX_EXPANSION` times, or :data:`EXPANSION_FLOOR` bytes, whichever is larger;
* an npz member whose header declares more samples than it stores, and an uncompressed HDF5
  dataset whose storage is smaller than its shape (unwritten or truncated), are refused;
* truncated or corrupt archives give a :class:`RecordError` naming the file.

Two roles may not read the same column (``columns={"u": "y"}`` would identify ``y`` from
itself). :meth:`Record.save` writes atomically (see :mod:`hystid.safeio`).

The package: :mod:`~hystid.records.record` (the record and its constants),
:mod:`~hystid.records.loading` (:func:`load_record` and friends),
:mod:`~hystid.records.csvfile` and :mod:`~hystid.records.arrays` (the formats, with the
hostile-file checks) and :mod:`~hystid.records.checks` (the sampling rate);
:meth:`Record.save` writes from :mod:`~hystid.records.record` itself. :class:`RecordError` is
defined with hystid's other errors in :mod:`hystid.errors`.
"""

from ..errors import RecordError
from .loading import load_piezo_sine_150v, load_record, parse_columns, parse_units, read_records
from .record import EXPANSION_FLOOR, FS_RTOL, MAX_EXPANSION, T_UNIFORM_RTOL, Record

__all__ = [
    "EXPANSION_FLOOR",
    "FS_RTOL",
    "MAX_EXPANSION",
    "T_UNIFORM_RTOL",
    "Record",
    "RecordError",
    "load_piezo_sine_150v",
    "load_record",
    "parse_columns",
    "parse_units",
    "read_records",
]
