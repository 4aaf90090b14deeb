"""Writing a record: CSV with a comment line, npz, MATLAB and HDF5, atomically."""

from __future__ import annotations

import json
import os

import numpy as np

from ..safeio import atomic_open, atomic_path
from .record import _META_PREFIX, Record


# --------------------------------------------------------------------------- writers
def _meta_line(rec: Record) -> str:
    name = " ".join(rec.name.splitlines())
    units = " ".join(f"{key}={value.replace(' ', '_')}" for key, value in rec.units.items())
    return f"# {_META_PREFIX} name={name}, fs={rec.fs!r}, units {units}\n"


def _save_csv(rec: Record, path: str | os.PathLike[str]) -> None:
    with atomic_open(path, "w", newline="\n") as out:
        out.write(_meta_line(rec))
        out.write("t,u,y\n")
        np.savetxt(out, np.column_stack([rec.t, rec.u, rec.y]), fmt="%.17g", delimiter=",")


def _save_npz(rec: Record, path: str | os.PathLike[str]) -> None:
    with atomic_open(path, "wb") as out:  # an open file keeps numpy from appending ".npz"
        np.savez(
            out,
            u=rec.u,
            y=rec.y,
            fs=np.float64(rec.fs),
            name=np.array(rec.name, dtype=np.str_),
            units=np.array(json.dumps(rec.units), dtype=np.str_),
        )


def _save_mat(rec: Record, path: str | os.PathLike[str]) -> None:
    from scipy.io import savemat

    with atomic_open(path, "wb") as out:
        savemat(
            out,
            {"u": rec.u, "y": rec.y, "fs": rec.fs, "name": rec.name,
             "units": json.dumps(rec.units)},
            oned_as="column",
        )


def _save_h5(rec: Record, path: str | os.PathLike[str]) -> None:
    import h5py

    with atomic_path(path) as tmp, h5py.File(tmp, "w") as out:
        out.create_dataset("u", data=rec.u)
        out.create_dataset("y", data=rec.y)
        out.attrs["fs"] = rec.fs
        out.attrs["name"] = rec.name
        out.attrs["units"] = json.dumps(rec.units)


