"""Records: validation, slicing, saving and loading, and the error messages for bad files."""

from pathlib import Path

import h5py
import numpy as np
import pytest
from scipy.io import savemat

from hystid.records import (
    T_UNIFORM_RTOL,
    Record,
    RecordError,
    load_piezo_sine_150v,
    load_record,
    read_records,
)

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
FORMATS = [".csv", ".txt", ".tsv", ".npz", ".mat", ".h5", ".hdf5"]


def make_record(n: int = 200, fs: float = 1000.0, name: str = "demo") -> Record:
    rng = np.random.default_rng(0)
    return Record(
        u=np.sin(np.arange(n) / 7.0) * 100,
        y=rng.normal(size=n),
        fs=fs,
        units={"u": "V", "y": "um"},
        name=name,
    )


def write_lines(path: Path, lines: list[str]) -> Path:
    path.write_text("\n".join(lines) + "\n")
    return path


def line_of(lines: list[str], text: str) -> int:
    """1-based line number of the first line equal to ``text``."""
    return lines.index(text) + 1


def csv_row(k: float, fs: float = 100.0, t: float | None = None) -> str:
    """Row ``t, u, y`` of sample ``k`` (time ``t`` instead of ``k / fs`` if given)."""
    t = k / fs if t is None else t
    return f"{t!r},{float(np.sin(k))!r},{float(np.cos(k))!r}"


def csv_lines(n: int = 20, fs: float = 100.0) -> list[str]:
    return ["# a comment", "", "t, u, y", *[csv_row(k, fs) for k in range(n)]]


def raises(match_parts: list[str], func, *args, **kwargs) -> str:
    """Call ``func``, expect a RecordError whose message contains every part; return it."""
    with pytest.raises(RecordError) as info:
        func(*args, **kwargs)
    message = str(info.value)
    for part in match_parts:
        assert part in message, f"{part!r} not in {message!r}"
    return message


# --------------------------------------------------------------------------- Record itself
def test_record_converts_and_exposes_time():
    rec = Record(u=[1, 2, 3], y=np.array([0.5, 1.5, 2.5], dtype=np.float32), fs=10)
    assert rec.u.dtype == np.float64 and rec.y.dtype == np.float64
    assert rec.n == len(rec) == 3
    np.testing.assert_allclose(rec.t, [0.0, 0.1, 0.2])
    span = rec.duration  # n / fs, the record's length in time
    assert span == pytest.approx(0.3)
    assert rec.units == {"u": "V", "y": "um"} and rec.name == "record"
    assert isinstance(rec.fs, float)
    assert "n=3" in repr(rec)


def test_default_units_are_not_shared():
    a, b = Record(u=[1.0], y=[2.0], fs=1.0), Record(u=[1.0], y=[2.0], fs=1.0)
    a.units["u"] = "kV"
    assert b.units["u"] == "V"


@pytest.mark.parametrize(
    ("kwargs", "parts"),
    [
        ({"u": np.zeros((3, 2)), "y": np.zeros(3)}, ["u", "(3, 2)", "1-D"]),
        ({"u": np.zeros(3), "y": np.zeros((3, 1))}, ["y", "(3, 1)", "1-D"]),
        ({"u": [], "y": []}, ["u is empty", "at least 1 sample"]),
        ({"u": [1.0, 2.0], "y": [1.0]}, ["different lengths", "u: 2", "y: 1"]),
        ({"u": [1.0, 2.0, np.nan], "y": [1.0, 2, 3]}, ["u", "sample 2", "nan"]),
        ({"u": [1.0, 2.0, 3.0], "y": [1.0, np.inf, 3]}, ["y", "sample 1", "inf"]),
        ({"u": [1.0], "y": [1.0], "fs": 0.0}, ["fs", "> 0"]),
        ({"u": [1.0], "y": [1.0], "fs": np.nan}, ["fs", "finite"]),
        ({"u": [1.0], "y": [1.0], "fs": "fast"}, ["fs must be a number"]),
    ],
)
def test_record_validation(kwargs, parts):
    kwargs = {"fs": 100.0, **kwargs}
    raises(parts, Record, **kwargs)


def test_slicing_returns_new_record():
    rec = make_record(100)
    part = rec[10:30]
    assert isinstance(part, Record) and part.n == 20
    np.testing.assert_array_equal(part.u, rec.u[10:30])
    np.testing.assert_array_equal(part.y, rec.y[10:30])
    assert (part.fs, part.units, part.name) == (rec.fs, rec.units, rec.name)
    part.u[0] = 1e9
    assert rec.u[10] != 1e9  # a copy, not a view
    assert rec[-5:].n == 5 and rec[::1].n == 100


def test_slicing_rejects_integers_steps_and_empty_slices():
    rec = make_record(10)
    with pytest.raises(TypeError, match="slices"):
        rec[3]
    with pytest.raises(ValueError, match="step 1"):
        rec[::2]
    with pytest.raises(ValueError, match="no samples"):
        rec[5:5]


def test_split_by_fraction_and_index():
    rec = make_record(100)
    train, val = rec.split()
    assert (train.n, val.n) == (50, 50)
    train, val = rec.split(0.7)
    assert (train.n, val.n) == (70, 30)
    np.testing.assert_array_equal(np.concatenate([train.y, val.y]), rec.y)
    train, val = rec.split(at=80)
    assert (train.n, val.n) == (80, 20)
    assert rec.split(0.001)[0].n == 1  # both parts keep at least one sample


@pytest.mark.parametrize("fraction", [0.0, 1.0, -0.5, 1.5, float("nan")])
def test_split_rejects_bad_fraction(fraction):
    with pytest.raises(ValueError, match="fraction"):
        make_record(10).split(fraction)


@pytest.mark.parametrize("at", [0, 10, -1, 2.5, True])
def test_split_rejects_bad_index(at):
    with pytest.raises(ValueError, match="at"):
        make_record(10).split(at=at)


def test_to_dict_rebuilds_the_record():
    rec = make_record(5)
    data = rec.to_dict()
    assert set(data) == {"u", "y", "fs", "units", "name"}
    again = Record(**data)
    np.testing.assert_array_equal(again.u, rec.u)
    assert again.fs == rec.fs and again.name == rec.name


# --------------------------------------------------------------------------- round trips
@pytest.mark.parametrize("suffix", FORMATS)
def test_round_trip(tmp_path, suffix):
    rec = Record(u=np.linspace(-1, 1, 301) ** 3 / 3, y=np.cos(np.arange(301.0)) + 1e-13,
                 fs=1234.5, units={"u": "N", "y": "m"}, name="trip, one")
    path = tmp_path / f"rec{suffix}"
    rec.save(path)
    back = load_record(path)
    np.testing.assert_array_equal(back.u, rec.u)  # exact: 17 digits in CSV
    np.testing.assert_array_equal(back.y, rec.y)
    assert back.fs == rec.fs
    assert back.units == rec.units
    assert back.name == rec.name
    assert load_record(str(path), name="other").name == "other"


def test_csv_layout(tmp_path):
    path = tmp_path / "rec.csv"
    make_record(3, fs=2.0).save(path)
    lines = path.read_text().splitlines()
    assert lines[0].startswith("# hystid record: name=demo, fs=2.0, units u=V y=um")
    assert lines[1] == "t,u,y"
    assert len(lines) == 5 and lines[3].startswith("0.5,")


def test_npz_loads_without_pickle(tmp_path):
    path = tmp_path / "rec.npz"
    make_record(10).save(path)
    with np.load(path, allow_pickle=False) as data:
        assert set(data.files) == {"u", "y", "fs", "name", "units"}
        assert data["name"].shape == () and data["name"].dtype.kind == "U"


def test_a_tab_separated_tsv_file_loads_and_saves_with_tabs(tmp_path):
    """``.tsv`` was refused while the same tab-separated text loaded as ``.txt``."""
    path = write_lines(tmp_path / "scan.tsv", ["t\tu\ty", *[f"{k / 100}\t{k % 7}\t{k % 5}"
                                                            for k in range(50)]])
    rec = load_record(path)
    assert rec.fs == pytest.approx(100.0) and rec.u[8] == 1.0 and rec.y[8] == 3.0
    rec.save(tmp_path / "again.tsv")
    assert "t\tu\ty" in (tmp_path / "again.tsv").read_text()


def test_save_unknown_extension(tmp_path):
    raises(["rec.xlsx", "unknown extension", ".csv"], make_record().save, tmp_path / "rec.xlsx")


def test_read_records(tmp_path):
    paths = []
    for k in range(2):
        paths.append(tmp_path / f"r{k}.npz")
        make_record(10 + k).save(paths[-1])
    assert [r.n for r in read_records(paths)] == [10, 11]
    assert read_records(paths[0])[0].n == 10


# --------------------------------------------------------------------------- CSV loading
def test_csv_with_comments_blank_lines_and_spaced_header(tmp_path):
    lines = csv_lines(20, fs=100.0)
    lines.insert(5, "   # an indented comment between rows")
    lines.insert(7, "")
    rec = load_record(write_lines(tmp_path / "data.csv", lines))
    assert rec.n == 20 and rec.fs == pytest.approx(100.0, rel=1e-12)
    assert rec.name == "data"
    assert rec.u[1] == np.sin(1)


def test_csv_header_is_case_insensitive_and_t_optional(tmp_path):
    lines = ["Y,U,extra", "1,2,a", "3,4,", "5,6,c"]
    rec = load_record(write_lines(tmp_path / "a.csv", lines), fs=50)
    np.testing.assert_array_equal(rec.u, [2, 4, 6])
    np.testing.assert_array_equal(rec.y, [1, 3, 5])
    assert rec.fs == 50.0


def test_csv_named_columns(tmp_path):
    lines = ["time,voltage,displacement"] + [f"{k * 0.01!r},{k},{2 * k}" for k in range(5)]
    path = write_lines(tmp_path / "named.csv", lines)
    rec = load_record(path, columns={"t": "time", "u": "voltage", "y": "Displacement"})
    np.testing.assert_array_equal(rec.y, 2 * rec.u)
    assert rec.fs == pytest.approx(100.0)
    raises(["named.csv", "line 1", "missing column 'u'", "voltage"], load_record, path, fs=1)


def test_csv_positions_without_header(tmp_path):
    lines = ["# no header", *[f",{k / 4!r},{k * 2},{k}" for k in range(8)]]
    rec = load_record(write_lines(tmp_path / "pos.csv", lines), columns={"t": 1, "u": 3, "y": 2})
    np.testing.assert_array_equal(rec.u, np.arange(8.0))
    np.testing.assert_array_equal(rec.y, 2 * np.arange(8.0))
    assert rec.fs == 4.0


def test_csv_positions_beyond_the_row(tmp_path):
    path = write_lines(tmp_path / "narrow.csv", ["1,2", "3,4"])
    raises(["narrow.csv", "line 1", "2 fields", "at least 6"], load_record, path,
           columns={"u": 0, "y": 5}, fs=1)


@pytest.mark.parametrize(
    "columns", [{"u": 0, "y": "y"}, {"u": 0}, {"u": 0, "y": -1}, {"v": "x"}, {"u": True, "y": 1}]
)
def test_bad_columns_argument(tmp_path, columns):
    path = write_lines(tmp_path / "c.csv", ["u,y", "1,2"])
    raises(["c.csv", "columns"], load_record, path, columns=columns, fs=1)


@pytest.mark.parametrize(
    ("text", "parts"),
    [
        ("nan", ["value 'nan' is not finite", "finite number"]),
        ("-inf", ["value '-inf' is not finite"]),
        ("1.2.3", ["value '1.2.3' is not a number"]),
        ("abc", ["value 'abc' is not a number"]),
        ("", ["empty value"]),
    ],
)
def test_csv_bad_value_names_line_and_column(tmp_path, text, parts):
    lines = csv_lines(30)
    row = lines[17].split(",")
    row[2] = text
    lines[17] = ",".join(row)
    path = write_lines(tmp_path / "bad.csv", lines)
    raises(["bad.csv", f"line {17 + 1}", "column 'y'", *parts], load_record, path)


def test_csv_several_non_finite_values_are_all_named(tmp_path):
    """Four NaN lines: the refusal named the first only, and the user fixed them one run at a
    time."""
    lines = csv_lines(30)
    for k in (5, 11, 17, 23):
        row = lines[k].split(",")
        row[2] = "nan"
        lines[k] = ",".join(row)
    path = write_lines(tmp_path / "nans.csv", lines)
    raises(["nans.csv", "line 6", "column 'y'", "3 more further on (lines 12, 18, 24)"],
           load_record, path)


def test_csv_bad_value_in_headerless_file_names_role(tmp_path):
    lines = ["# comment", *[f",{k / 4!r},{k * 2},{k}" for k in range(8)]]
    lines[4] = ",0.75,oops,3"
    path = write_lines(tmp_path / "pos.csv", lines)
    raises(["pos.csv", "line 5", "column 'y'", "'oops'"], load_record, path,
           columns={"t": 1, "u": 3, "y": 2})


def test_csv_missing_column_lists_found(tmp_path):
    lines = ["# x", "t,u,z", "0,1,2", "1,1,2"]
    raises(["miss.csv", "line 2", "missing column 'y'", "'t', 'u', 'z'"],
           load_record, write_lines(tmp_path / "miss.csv", lines))


def test_csv_wrong_number_of_fields(tmp_path):
    lines = csv_lines(20)
    lines[12] += ",99"
    raises(["rows.csv", "line 13", "4 fields", "expected 3"],
           load_record, write_lines(tmp_path / "rows.csv", lines))
    lines = csv_lines(20)
    lines[9] = lines[9].rsplit(",", 1)[0]
    raises(["rows.csv", "line 10", "2 fields", "expected 3"],
           load_record, write_lines(tmp_path / "rows.csv", lines))


@pytest.mark.parametrize(
    ("sep", "name"), [(";", "semicolon"), ("\t", "tab"), (" ", "space"), ("   ", "blanks")]
)
def test_csv_other_delimiters_are_detected(tmp_path, sep, name):
    rows = [f"{k / 100!r}{sep}{float(np.sin(k))!r}{sep}{float(np.cos(k))!r}" for k in range(20)]
    rec = load_record(write_lines(tmp_path / f"{name}.txt", ["# x", f"t{sep}u{sep}y", *rows]))
    np.testing.assert_array_equal(rec.u, np.sin(np.arange(20)))
    np.testing.assert_array_equal(rec.y, np.cos(np.arange(20)))
    assert rec.fs == pytest.approx(100.0)
    # a bad cell is located by line and column whatever the delimiter
    rows[6] = rows[6].replace(f"{sep}{float(np.cos(6))!r}", f"{sep}oops")
    raises([f"{name}.txt", "line 10", "column 'y'", "'oops'"], load_record,
           write_lines(tmp_path / f"{name}.txt", ["# x", "", f"t{sep}u{sep}y", *rows]))


def test_csv_quoted_numbers_and_names(tmp_path):
    lines = ['"t";"u";"y"', *[f'"{k / 10!r}";"{k}";{2 * k}' for k in range(6)]]
    rec = load_record(write_lines(tmp_path / "quoted.csv", lines))
    np.testing.assert_array_equal(rec.u, np.arange(6.0))
    np.testing.assert_array_equal(rec.y, 2 * np.arange(6.0))
    lines = ["u,y,note", '1,2,"a, quoted, note"', '3,4,"b"']  # commas inside quotes
    rec = load_record(write_lines(tmp_path / "note.csv", lines), fs=1)
    np.testing.assert_array_equal(rec.u, [1, 3])
    lines[1] = '1,"2,3'  # a quote left open
    raises(["note.csv", "line 2", "quote"], load_record,
           write_lines(tmp_path / "note.csv", lines), fs=1)
    lines = ["u,y", '"1,5",2']  # a decimal comma is not a number
    raises(["dec.csv", "line 2", "column 'u'", "'1,5'", "not a number"], load_record,
           write_lines(tmp_path / "dec.csv", lines), fs=1)


def test_csv_decreasing_and_repeated_t(tmp_path):
    lines = csv_lines(20, fs=100.0)
    bad = line_of(lines, csv_row(8))
    lines[bad - 1] = csv_row(8, t=0.05)
    raises(["dec.csv", f"line {bad}", "column 't'", "decreases", "strictly increasing"],
           load_record, write_lines(tmp_path / "dec.csv", lines))
    lines = csv_lines(20, fs=100.0)
    lines[bad - 1] = csv_row(8, t=0.07)
    raises(["rep.csv", f"line {bad}", "column 't'", "repeats"],
           load_record, write_lines(tmp_path / "rep.csv", lines))


def test_csv_non_uniform_t(tmp_path):
    lines = csv_lines(40, fs=100.0)
    late = line_of(lines, csv_row(11))
    lines[late - 1] = csv_row(11, t=0.111)  # 10 % of a step late
    raises(["late.csv", f"line {late}", "column 't'", "not uniform"],
           load_record, write_lines(tmp_path / "late.csv", lines))


def test_csv_t_within_tolerance_loads(tmp_path):
    jitter = 0.2 * T_UNIFORM_RTOL * np.cos(np.arange(50))  # printing/clock jitter
    t = (np.arange(50) + jitter) / 5000.0
    lines = ["t,u,y"] + [f"{tk:.9g},1,2" for tk in t]
    rec = load_record(write_lines(tmp_path / "jitter.csv", lines))
    assert rec.fs == pytest.approx(5000.0, rel=1e-3)


def test_csv_empty_and_header_only(tmp_path):
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    raises(["empty.csv", "no data rows"], load_record, empty, fs=1)
    raises(["comments.csv", "no data rows"], load_record,
           write_lines(tmp_path / "comments.csv", ["# only", "", "# comments"]), fs=1)
    raises(["head.csv", "no data rows"], load_record,
           write_lines(tmp_path / "head.csv", ["# c", "t,u,y", ""]))


def test_csv_fs_mismatch_and_agreement(tmp_path):
    path = write_lines(tmp_path / "fs.csv", csv_lines(20, fs=100.0))
    message = raises(["fs.csv", "fs mismatch", "101", "100"], load_record, path, fs=101.0)
    assert "99.99" in message or "100.0" in message
    assert load_record(path, fs=100.0).fs == 100.0


def test_csv_saved_comment_fs_is_checked(tmp_path):
    path = tmp_path / "meta.csv"
    make_record(20, fs=100.0).save(path)
    assert load_record(path, fs=100.0).fs == 100.0
    raises(["meta.csv", "fs mismatch"], load_record, path, fs=200.0)
    text = path.read_text().replace("fs=100.0", "fs=250.0", 1)
    path.write_text(text)
    raises(["meta.csv", "fs mismatch", "line 1", "250.0"], load_record, path)


def test_csv_without_t_needs_fs(tmp_path):
    path = write_lines(tmp_path / "not.csv", ["u,y", "1,2", "3,4"])
    raises(["not.csv", "fs=", "--fs"], load_record, path)
    assert load_record(path, fs=8.0).fs == 8.0


def test_large_csv_round_trips_exactly(tmp_path):
    n = 50_000
    path = tmp_path / "big.csv"
    src = Record(u=np.sin(np.arange(n) / 100), y=np.cos(np.arange(n) / 100), fs=5000.0)
    src.save(path)
    rec = load_record(path)
    assert rec.n == n and rec.fs == 5000.0
    np.testing.assert_array_equal(rec.u, src.u)
    np.testing.assert_array_equal(rec.y, src.y)


# --------------------------------------------------------------------------- array formats
def write_npz(path: Path, **arrays) -> Path:
    np.savez(path, **arrays)
    return path


def write_mat(path: Path, **arrays) -> Path:
    savemat(path, arrays)
    return path


def write_h5(path: Path, attrs: dict | None = None, **arrays) -> Path:
    with h5py.File(path, "w") as out:
        for key, value in arrays.items():
            out.create_dataset(key, data=value)
        out.attrs.update(attrs or {})
    return path


WRITERS = {
    ".npz": write_npz,
    ".mat": write_mat,
    ".h5": write_h5,
}
KIND = {".npz": "array", ".mat": "variable", ".h5": "dataset"}


@pytest.mark.parametrize("suffix", WRITERS)
def test_arrays_with_t_instead_of_fs(tmp_path, suffix):
    path = WRITERS[suffix](tmp_path / f"t{suffix}", u=np.ones(10), y=np.zeros(10),
                           t=np.arange(10) / 20.0 + 3.0)
    rec = load_record(path)
    assert rec.fs == pytest.approx(20.0) and rec.n == 10 and rec.name == "t"


@pytest.mark.parametrize("suffix", WRITERS)
def test_arrays_column_vectors_are_squeezed(tmp_path, suffix):
    path = WRITERS[suffix](tmp_path / f"col{suffix}", u=np.ones((10, 1)), y=np.zeros((1, 10)),
                           fs=np.array([5.0]))
    assert load_record(path).n == 10


@pytest.mark.parametrize("suffix", WRITERS)
def test_arrays_unequal_lengths(tmp_path, suffix):
    path = WRITERS[suffix](tmp_path / f"len{suffix}", u=np.ones(10), y=np.zeros(9), fs=5.0)
    raises([path.name, "different lengths", "u: 10", "y: 9"], load_record, path)


@pytest.mark.parametrize("suffix", WRITERS)
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_arrays_non_finite(tmp_path, suffix, bad):
    y = np.zeros(10)
    y[6] = bad
    path = WRITERS[suffix](tmp_path / f"nan{suffix}", u=np.ones(10), y=y, fs=5.0)
    raises([path.name, f"{KIND[suffix]} 'y'", "index 6", "not finite"], load_record, path)


@pytest.mark.parametrize("suffix", WRITERS)
def test_arrays_missing_signal(tmp_path, suffix):
    path = WRITERS[suffix](tmp_path / f"miss{suffix}", u=np.ones(10), x=np.zeros(10), fs=5.0)
    raises([path.name, f"missing {KIND[suffix]} 'y'", "'u'", "'x'"], load_record, path)


@pytest.mark.parametrize("suffix", WRITERS)
def test_arrays_without_fs_or_t(tmp_path, suffix):
    path = WRITERS[suffix](tmp_path / f"nofs{suffix}", u=np.ones(10), y=np.zeros(10))
    raises([path.name, "fs=", "--fs"], load_record, path)
    assert load_record(path, fs=7.0).fs == 7.0


@pytest.mark.parametrize("suffix", WRITERS)
def test_arrays_fs_mismatch(tmp_path, suffix):
    path = WRITERS[suffix](tmp_path / f"mis{suffix}", u=np.ones(10), y=np.zeros(10), fs=5.0)
    raises([path.name, "fs mismatch", "6.0", "5.0"], load_record, path, fs=6.0)
    path = WRITERS[suffix](tmp_path / f"mist{suffix}", u=np.ones(10), y=np.zeros(10),
                           t=np.arange(10) / 5.0)
    raises([path.name, "fs mismatch"], load_record, path, fs=6.0)


@pytest.mark.parametrize("suffix", WRITERS)
def test_arrays_non_uniform_and_decreasing_t(tmp_path, suffix):
    t = np.arange(10) / 5.0
    t[4] += 0.1 / 5.0
    path = WRITERS[suffix](tmp_path / f"nu{suffix}", u=np.ones(10), y=np.zeros(10), t=t)
    raises([path.name, f"{KIND[suffix]} 't'", "index 4", "not uniform"], load_record, path)
    t[4] = t[2]
    path = WRITERS[suffix](tmp_path / f"dec{suffix}", u=np.ones(10), y=np.zeros(10), t=t)
    raises([path.name, "index 4", "decreases"], load_record, path)


@pytest.mark.parametrize("suffix", WRITERS)
def test_arrays_renamed_by_columns(tmp_path, suffix):
    path = WRITERS[suffix](tmp_path / f"ren{suffix}", force=np.ones(4), disp=np.zeros(4), fs=2.0)
    rec = load_record(path, columns={"u": "force", "y": "disp"})
    assert rec.n == 4
    raises([path.name, "positions"], load_record, path, columns={"u": 0, "y": 1})


def test_npz_object_array_is_refused(tmp_path):
    u = np.empty(3, dtype=object)
    u[:] = [1.0, 2.0, 3.0]
    path = tmp_path / "obj.npz"
    np.savez(path, u=u, y=np.zeros(3), fs=1.0)  # savez pickles object arrays
    raises(["obj.npz", "'u'", "object array", "pickle"], load_record, path)


def test_string_array_is_refused(tmp_path):
    path = write_npz(tmp_path / "str.npz", u=np.array(["a", "b"]), y=np.zeros(2), fs=1.0)
    raises(["str.npz", "'u'", "dtype", "real numbers"], load_record, path)


def test_corrupt_files(tmp_path):
    for suffix in [".npz", ".mat", ".h5"]:
        path = tmp_path / f"junk{suffix}"
        path.write_bytes(b"this is not a binary record file at all" * 10)
        raises([path.name, "not a readable"], load_record, path)


def test_h5_group_fs_dataset_and_attribute(tmp_path):
    path = tmp_path / "grp.h5"
    with h5py.File(path, "w") as out:
        first = out.create_group("runs/first")
        first.create_dataset("u", data=np.ones((6, 1)))
        first.create_dataset("y", data=np.zeros((6, 1)))
        first.create_dataset("fs", data=[750.0])
        second = out.create_group("second")
        second.create_dataset("u", data=np.ones(4))
        second.create_dataset("y", data=np.zeros(4))
        second.attrs["fs"] = 10.0
    rec = load_record(f"{path}:runs/first")
    assert (rec.n, rec.fs, rec.name) == (6, 750.0, "grp:runs/first")
    assert load_record(f"{path}:/second").fs == 10.0
    raises(["grp.h5", "no group 'third'", "second"], load_record, f"{path}:third")
    raises(["grp.h5", "missing dataset 'u'"], load_record, path)


# --------------------------------------------------------------------------- files and paths
def test_missing_file(tmp_path):
    for suffix in FORMATS:
        raises([f"absent{suffix}", "does not exist"], load_record, tmp_path / f"absent{suffix}")
    raises(["absent.h5", "does not exist"], load_record, f"{tmp_path / 'absent.h5'}:group")


def test_unknown_extension(tmp_path):
    path = tmp_path / "rec.xls"
    path.write_text("u,y\n1,2\n")
    raises(["rec.xls", "unknown extension '.xls'", ".csv", ".npz", ".h5"], load_record, path)
    raises(["noext", "unknown extension none"], load_record, tmp_path / "noext")


# --------------------------------------------------------------------------- shared data
def shared(relative: str) -> Path:
    path = SHARED / relative
    if not path.exists():
        pytest.skip(f"../shared/data not found: {path}")
    return path


def test_real_piezo_record():
    path = shared("real/piezo_sine_150V_1Hz/hysteresis_v_150_1hz.csv")
    rec = load_piezo_sine_150v(path)
    assert rec.n == 50_001
    assert rec.fs == pytest.approx(5000.0, rel=1e-3)
    assert 19.0 < np.max(np.abs(rec.y)) < 20.5
    assert 140 < np.max(np.abs(rec.u)) < 160  # volts
    assert rec.units == {"u": "V", "y": "um"}
    assert rec.name == "piezo_sine_150V_1Hz"
    assert load_piezo_sine_150v(path.parent).n == rec.n


def test_bouc_wen_multisine_group():
    path = shared("benchmarks/bouc_wen/test.h5")
    rec = load_record(f"{path}:multisine")
    assert rec.n == 8192
    assert rec.fs == 750.0
    assert np.all(np.isfinite(rec.u)) and np.std(rec.y) > 0


def test_units_stated_on_load_replace_the_default_label(tmp_path):
    path = tmp_path / "bw.csv"
    path.write_text("t,u,y\n0,1,0.001\n0.001,2,0.002\n0.002,1,0.001\n")
    assert load_record(path).units == {"u": "V", "y": "um"}  # the default label
    rec = load_record(path, units={"u": "N", "y": "m"})
    assert rec.units == {"u": "N", "y": "m"}
    assert load_record(path, units={"y": "nm"}).units == {"u": "V", "y": "nm"}
    with pytest.raises(RecordError, match=r"bw.csv.*units=.*expected a mapping of 'u'"):
        load_record(path, units={"x": "m"})


@pytest.mark.parametrize("header, units", [
    ("t,cmd_mV,pos_nm", {"u": "mV", "y": "nm"}),   # columns named, units after an underscore
    ("t,u [V],y [nm]", {"u": "V", "y": "nm"}),     # the role and its unit in brackets
    ("t,u (mV),y/um", {"u": "mV", "y": "um"}),
    ("t,drive_signal,y", {"u": "V", "y": "um"}),   # 'signal' is no unit: the default label
])
def test_units_named_in_the_header_label_the_record(tmp_path, header, units):
    path = tmp_path / "stage.csv"
    path.write_text(f"{header}\n0,1,0.5\n0.001,2,1.0\n0.002,1,0.5\n")
    u, y = header.split(",")[1:]
    columns = None if u.startswith("u") else {"u": u, "y": y}
    rec = load_record(path, columns=columns)
    assert rec.units == units and rec.fs == 1000.0
    assert load_record(path, columns=columns, units={"y": "m"}).units == {**units, "y": "m"}


@pytest.mark.parametrize("label, scale", [("t_ms", 1e3), ("t [us]", 1e6), ("t (s)", 1.0)])
def test_a_time_column_labelled_in_ms_or_us_is_read_in_that_unit(tmp_path, label, scale):
    path = tmp_path / "stage.csv"
    t = np.arange(50) / 5000.0 * scale  # 5 kHz, written in the label's unit
    np.savetxt(path, np.c_[t, np.sin(t), np.cos(t)], delimiter=",", header=f"{label},u,y",
               comments="")
    assert load_record(path).fs == pytest.approx(5000.0, rel=1e-9)


def test_a_saved_record_keeps_its_stated_units_over_its_header(tmp_path):
    rec = Record(np.arange(5.0), np.arange(5.0), 100.0, {"u": "N", "y": "m"}, "saved")
    rec.save(tmp_path / "r.csv")
    assert load_record(tmp_path / "r.csv").units == {"u": "N", "y": "m"}
