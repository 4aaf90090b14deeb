"""An independent hostile-input audit of the ``hystid`` command line and API.

Generates hostile cases (bad options, corrupt and malicious record and model files, unstable
models, huge records, concurrent writers, API misuse) in a scratch folder outside the
repository, runs each through ``python -m hystid`` (or a short Python snippet for the API) with
a timeout, and classifies the outcome:

* ``clear-error``: exit status 2, an ``error:`` line, no traceback;
* ``sound``: exit status 0 where a result is acceptable (with the warning the case deserves,
  when it deserves one);
* ``traceback``: a Python traceback, or an exit status other than 0 and 2;
* ``hang``: still running at the timeout;
* ``silent-wrong``: exit status 0 where the case must be refused or warned about, and it was
  not;
* ``overwrite``: two writers to one output both succeeded, or a file put into ``--out`` during
  a run was replaced.

Run from the repository's root::

    python benchmarks/audit_hostile.py --out /tmp/audit.json [--timeout 60] [--only WORD]

It prints a table and the counts per class, and writes them as JSON to ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import textwrap
import time
import zipfile
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CLASSES = ("clear-error", "sound", "traceback", "hang", "silent-wrong", "overwrite")


@dataclass
class Case:
    """One hostile case: a command line (or API snippet) and what an answer must be.

    Parameters
    ----------
    name : str
        Short label.
    argv : list of str
        Arguments of ``python -m hystid`` (or of ``python -c`` for an API snippet).
    expect : str
        ``"error"`` (must be refused), ``"warn"`` (refused, or exit 0 with a warning),
        ``"ok"`` (exit 0, or a clear refusal) or ``"any"``.
    api : bool
        ``argv`` is a Python snippet run with ``python -c``.
    """

    name: str
    argv: list[str]
    expect: str = "error"
    api: bool = False
    outcome: dict = field(default_factory=dict)


# --------------------------------------------------------------------------- running
def run(argv: list[str], timeout: float, api: bool = False) -> dict:
    """Run one command; return status, the tail of stderr and the seconds taken.

    Parameters
    ----------
    argv : list of str
        The arguments.
    timeout : float
        Seconds before the process is killed and called a hang.
    api : bool
        Run ``python -c argv[0]`` instead of ``python -m hystid argv``.

    Returns
    -------
    dict
        Keys ``status`` (None on a timeout), ``stderr``, ``stdout``, ``seconds``.
    """
    cmd = [sys.executable, "-c", argv[0]] if api else [sys.executable, "-m", "hystid", *argv]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout)
        status = proc.returncode
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, 9)
        out, err = proc.communicate()
        status = None
    return {"status": status, "stdout": out[-2000:], "stderr": err[-4000:],
            "seconds": round(time.perf_counter() - t0, 2)}


def classify(case: Case, res: dict) -> str:
    """The class of one outcome (see the module's docstring).

    Parameters
    ----------
    case : Case
        The case and what it expects.
    res : dict
        What :func:`run` returned.

    Returns
    -------
    str
        One of :data:`CLASSES`.
    """
    if res["status"] is None:
        return "hang"
    err = res["stderr"]
    if "Traceback" in err or res["status"] not in (0, 2):
        return "traceback"
    if res["status"] == 2:
        lines = [ln for ln in err.splitlines() if "error" in ln.lower()]
        return "clear-error" if lines else "traceback"
    warned = "warning" in (err + res["stdout"]).lower()
    if case.expect == "error" or (case.expect == "warn" and not warned):
        return "silent-wrong"
    return "sound"


# --------------------------------------------------------------------------- generating
def _record(n: int, fs: float = 30000.0, seed: int = 0, shift: float = 0.0) -> tuple:
    """A hysteretic stage-like record: input from rest, output a lagged loop."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    u = 3.0 * (1 - np.cos(2 * np.pi * 40 * t)) + 0.5 * (1 - np.cos(2 * np.pi * 230 * t))
    y = np.zeros(n)
    w = 0.0
    for k in range(1, n):  # a crude backlash-like loop, enough to be identifiable-looking
        w += 0.6 * (u[k] - u[k - 1]) + 0.1 * abs(u[k] - u[k - 1]) * (0.3 * u[k - 1] - w)
        y[k] = 0.8 * y[k - 1] + 0.2 * w
    return t, u + shift, y + 1e-3 * rng.standard_normal(n)


def _write_csv(path: Path, t, u, y) -> Path:
    np.savetxt(path, np.column_stack([t, u, y]), delimiter=",", header="t,u,y", comments="",
               fmt="%.10g")
    return path


def _model_doc(base: dict, **changes) -> dict:
    doc = json.loads(json.dumps(base))
    for key, value in changes.items():
        target = doc
        *path, last = key.split(".")
        for part in path:
            target = target[part]
        target[last] = value
    return doc


def _npz_with_flags(src: Path, dst: Path, flag_bits: int = 0, method: int | None = None) -> Path:
    """Copy an npz, setting general-purpose flag bits or the compression method in its headers."""
    data = bytearray(src.read_bytes())
    for sig, flag_at, method_at in ((b"PK\x03\x04", 6, 8), (b"PK\x01\x02", 8, 10)):
        start = 0
        while (i := data.find(sig, start)) >= 0:
            if flag_bits:
                data[i + flag_at] |= flag_bits
            if method is not None:
                data[i + method_at:i + method_at + 2] = method.to_bytes(2, "little")
            start = i + 4
    dst.write_bytes(bytes(data))
    return dst


def build_cases(work: Path, big: bool = True) -> list[Case]:
    """Write the files the cases need into ``work`` and list the cases.

    Parameters
    ----------
    work : pathlib.Path
        Scratch folder.
    big : bool
        Include the 1e7-sample records (hundreds of MB on disk).

    Returns
    -------
    list of Case
    """
    t, u, y = _record(6000)
    rec = _write_csv(work / "rec.csv", t, u, y)
    subprocess.run([sys.executable, "-m", "hystid", "identify", str(rec), "--quiet", "--out",
                    str(work / "rep")], cwd=ROOT, check=True, capture_output=True)
    base = json.loads((work / "rep" / "model.json").read_text())
    cases: list[Case] = []

    def model_case(name: str, doc: dict | str, expect: str = "error") -> None:
        path = work / f"model_{name}.json"
        path.write_text(doc if isinstance(doc, str) else json.dumps(doc))
        cases.append(Case(f"model {name}", ["simulate", "--model", str(path), "--input",
                                            str(rec), "--out", str(work / f"sim_{name}.csv")],
                          expect))

    # options
    opts = [
        ("crop 0:1e308", ["identify", str(rec), "--crop", "0:1e308"], "ok"),
        ("crop 1e308:2e308", ["identify", str(rec), "--crop", "1e308:2e308"], "error"),
        ("crop nan:1", ["identify", str(rec), "--crop", "nan:1"], "error"),
        ("crop -1:inf", ["identify", str(rec), "--crop=-1:inf"], "error"),
        ("simulate seconds 1e-9", ["simulate", "--seconds", "1e-9", "--seed", "0", "--out",
                                   str(work / "s1.csv")], "error"),
        ("simulate seconds 1e300", ["simulate", "--seconds", "1e300", "--seed", "0", "--out",
                                    str(work / "s2.csv")], "error"),
        ("demo seconds 0.001", ["demo", "--seconds", "0.001", "--out", str(work / "d1")],
         "error"),
        ("demo seconds 1e-300", ["demo", "--seconds", "1e-300", "--out", str(work / "d2")],
         "error"),
        ("fleet seed -1", ["fleet", "identify", str(rec), "--seed=-1", "--out",
                           str(work / "f1"), "--workers", "1"], "error"),
        ("fleet seed 2**70", ["fleet", "identify", str(rec), f"--seed={2**70}", "--out",
                              str(work / "f2"), "--workers", "1"], "error"),
        ("structure q1=1e9", ["identify", str(rec), "--structure", "q1=1000000000"], "error"),
        ("structure q1 longer than record", ["identify", str(rec), "--structure", "q1=900",
                                             "--crop", "0:0.02"], "error"),
        ("fs 1e-300", ["identify", str(rec), "--fs", "1e-300"], "any"),
        ("holdout 0.999", ["identify", str(rec), "--holdout", "0.999"], "error"),
        ("structure n1a=11", ["identify", str(rec), "--structure", "n1a=11"], "error"),
        ("fs 0", ["identify", str(rec), "--fs", "0"], "error"),
        ("identify a folder", ["identify", str(work)], "error"),
        ("diagnose crop 0:1e308", ["diagnose", str(rec), "--crop", "0:1e308"], "error"),
        ("diagnose seconds-like crop nan", ["diagnose", str(rec), "--crop", "nan:"], "error"),
    ]
    cases += [Case(n, a, e) for n, a, e in opts]

    # record files
    np.savez(work / "rec.npz", t=t, u=u, y=y)
    np.savez_compressed(work / "recz.npz", t=t, u=u, y=y)
    _npz_with_flags(work / "rec.npz", work / "encrypted.npz", flag_bits=1)
    _npz_with_flags(work / "rec.npz", work / "method99.npz", method=99)
    _npz_with_flags(work / "recz.npz", work / "method14.npz", method=14)
    (work / "empty.csv").write_text("")
    (work / "header_only.csv").write_text("t,u,y\n")
    (work / "nan.csv").write_text("t,u,y\n" + "".join(f"{k},nan,1\n" for k in range(100)))
    (work / "binary.csv").write_bytes(os.urandom(4096))
    with zipfile.ZipFile(work / "bomb.npz", "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("u.npy", b"\x93NUMPY" + b"\0" * (200 << 20))
    (work / "nocol.csv").write_text("t,a,b\n" + "".join(f"{k},{k},{k}\n" for k in range(100)))
    (work / "inf.csv").write_text("t,u,y\n" + "".join(f"{k},{k % 7},inf\n" for k in range(100)))
    (work / "huge_values.csv").write_text("t,u,y\n" + "".join(
        f"{k / 1000},{(k % 17) * 1e300},{(k % 5) * 1e300}\n" for k in range(2000)))
    for name, expect in (("encrypted.npz", "error"), ("method99.npz", "error"),
                         ("method14.npz", "error"), ("empty.csv", "error"),
                         ("header_only.csv", "error"), ("nan.csv", "error"),
                         ("binary.csv", "error"), ("bomb.npz", "error"), ("nocol.csv", "error"),
                         ("inf.csv", "error"), ("huge_values.csv", "error")):
        cases.append(Case(f"record {name}", ["identify", str(work / name)], expect))
    cases.append(Case("record huge_values.csv --model pi",
                      ["identify", str(work / "huge_values.csv"), "--model", "pi"]))
    fifo = work / "fifo.csv"
    os.mkfifo(fifo)
    cases.append(Case("record FIFO", ["identify", str(fifo)], "error"))
    (work / "zero.csv").symlink_to("/dev/zero")
    cases.append(Case("record -> /dev/zero", ["identify", str(work / "zero.csv")], "error"))

    # input outliers, drift
    u1 = u.copy()
    u1[3000] = 100.0
    _write_csv(work / "u_outlier.csv", t, u1, y)
    cases.append(Case("input outlier sample", ["identify", str(work / "u_outlier.csv")], "warn"))
    y1 = y.copy()
    y1[2000:2100] += 5.0
    _write_csv(work / "y_burst.csv", t, u, y1)
    cases.append(Case("output burst", ["identify", str(work / "y_burst.csv")], "warn"))
    _write_csv(work / "drift.csv", t, u, np.linspace(0, 3, len(t))
               + 1e-3 * np.random.default_rng(1).standard_normal(len(t)))
    cases.append(Case("output only drift", ["identify", str(work / "drift.csv")], "warn"))

    # model files
    for label, value in (("string", "hello"), ("number", 3), ("list", [1, 2])):
        model_case(f"provenance {label}", _model_doc(base, provenance=value), "ok")
    deep = json.dumps(_model_doc(base, provenance=0)).replace(
        '"provenance": 0', '"provenance": ' + "[" * 100000 + "]" * 100000)
    model_case("provenance nested", deep, "error")
    model_case("L2 pole on unit circle", _model_doc(base, **{"params.a21": 0.0,
                                                             "params.a22": 1.0}))
    model_case("L2 pole at 1", _model_doc(base, **{"params.a21": -2.0, "params.a22": 1.0}))
    model_case("L2 pole 1.01", _model_doc(base, **{"params.a21": -2.02, "params.a22": 1.0201}))
    model_case("L2 pole 1.05", _model_doc(base, **{"params.a21": -2.1, "params.a22": 1.1025}))
    model_case("L1 pole 1.2", _model_doc(base, **{"params.a11": -1.2}))
    model_case("alpha < 0", _model_doc(base, **{"params.alpha": -0.5}))
    model_case("alpha huge", _model_doc(base, **{"params.alpha": 1e300}))
    model_case("g0 1e200", _model_doc(base, **{"params.g0": 1e200}))
    model_case("offset 1e308", _model_doc(base, offset=1e308))
    model_case("u_rest 1e308", _model_doc(base, u_rest=1e308))
    model_case("fs 1e-300", _model_doc(base, fs=1e-300))
    model_case("q1 1e9", _model_doc(base, **{"structure.q1": 10**9}))
    model_case("q1 longer than record", _model_doc(base, **{"structure.q1": 50000}))
    model_case("n2a 10000", _model_doc(base, **{"structure.n2a": 10000}))
    model_case("envelope 1e308", _model_doc(base, **{"envelope.u_max": 1e308}))
    model_case("not json", "{")
    model_case("params a list", _model_doc(base, params=[1, 2, 3]))
    model_case("version 2", _model_doc(base, version=2))
    model_case("kind unknown", _model_doc(base, kind="preisach"))
    model_case("params nan text", json.dumps(_model_doc(base)).replace(
        '"alpha": ', '"alpha": NaN, "x": '))
    delay = work / "model_delay900.json"
    delay.write_text(json.dumps(_model_doc(base, **{"structure.q1": 900})))
    _write_csv(work / "short.csv", t[:1000], u[:1000], y[:1000])
    cases.append(Case("model delay longer than input", [
        "simulate", "--model", str(delay), "--input", str(work / "short.csv"), "--out",
        str(work / "sim_delay.csv")]))
    unstable = work / "model_L2 pole 1.05.json"
    cases.append(Case("diagnose --model unstable", ["diagnose", str(rec), "--model",
                                                    str(unstable)]))
    fifo_model = work / "model_fifo.json"
    os.mkfifo(fifo_model)
    cases.append(Case("model FIFO", ["simulate", "--model", str(fifo_model), "--input",
                                     str(rec), "--out", str(work / "sim_fifo.csv")]))
    (work / "model_zero.json").symlink_to("/dev/zero")
    cases.append(Case("model -> /dev/zero", ["simulate", "--model",
                                             str(work / "model_zero.json"), "--input", str(rec),
                                             "--out", str(work / "sim_zero.csv")]))
    (work / "model_big.json").write_text(" " * (300 << 20) + "{}")
    cases.append(Case("model 300 MB", ["simulate", "--model", str(work / "model_big.json"),
                                       "--input", str(rec), "--out", str(work / "sim_big.csv")]))
    pi = {"format": "hystid-model", "version": 1, "kind": "pi", "name": "pi",
          "structure": {"n_operators": 3, "n1a": 1, "n1b": 1, "n2a": 2, "n2b": 1, "q1": 1,
                        "q2": 0},
          "params": {"a11": -0.5, "mu1": 1.0, "mu2": 0.5, "mu3": 0.2, "a21": -1.6, "a22": 0.92},
          "thresholds": [0.0, 1e300, 2e300], "fs": 30000.0}
    model_case("PI thresholds 1e300", pi)

    # API
    pre = "import numpy as np, hystid; from hystid.identify import identify; "
    api = [
        ("identify(None)", "identify(None)"),
        ("identify(path str)", f"identify({str(rec)!r})"),
        ("identify(ndarray)", "identify(np.zeros((100, 2)))"),
        ("identify(rec, structure=3)",
         f"identify(hystid.records.load_record({str(rec)!r}), structure=3)"),
        ("identify(rec, method=7)",
         f"identify(hystid.records.load_record({str(rec)!r}), method=7)"),
        ("Structure(q1=1e9) identify",
         f"from hystid.model import Structure; identify(hystid.records.load_record("
         f"{str(rec)!r}), structure=Structure(q1=10**9))"),
        ("load_model(/dev/zero)", f"hystid.load_model({str(work / 'model_zero.json')!r})"),
        ("unstable model simulate",
         "from hystid.model import DuhemSandwich; import warnings; warnings.simplefilter('error');"
         " DuhemSandwich([0.8, 0.1, 0.004, -0.5, -2.1, 1.1025]).simulate(np.sin(np.arange("
         "6000) / 50.0))"),
    ]
    for name, code in api:
        snippet = pre + textwrap.dedent(f"""
            import sys
            try:
                {code}
            except (ValueError, TypeError, Warning) as err:
                print(f"hystid api: error: {{type(err).__name__}}: {{err}}", file=sys.stderr)
                sys.exit(2)
            """)
        cases.append(Case(f"api {name}", [snippet], "error", api=True))

    # huge records
    if big:
        n = 10_000_000
        tb = np.arange(n) / 30000.0
        ub = 3.0 * (1 - np.cos(2 * np.pi * 40 * tb))
        np.savez(work / "big.npz", t=tb, u=ub, y=0.1 * ub)
        with open(work / "big.csv", "w") as out:
            out.write("u,y\n")
            block = np.column_stack([ub[:n // 10], 0.1 * ub[:n // 10]])
            text = "\n".join(f"{a:.6g},{b:.6g}" for a, b in block) + "\n"
            for _ in range(10):
                out.write(text)
        for name in ("big.npz", "big.csv"):
            extra = ["--fs", "30000"] if name.endswith(".csv") else []
            for method in ("batch", "online"):
                cases.append(Case(f"1e7 samples {name} {method}",
                                  ["identify", str(work / name), "--method", method, *extra],
                                  "any"))
            cases.append(Case(f"1e7 samples {name} diagnose",
                              ["diagnose", str(work / name), "--quiet", *extra], "any"))
    return cases


# --------------------------------------------------------------------------- races
def race(work: Path, name: str, argv: list[str], out: Path, timeout: float) -> dict:
    """Start the same writer twice a second apart; both succeeding is an overwrite.

    Parameters
    ----------
    work : pathlib.Path
        Scratch folder.
    name : str
        Label.
    argv : list of str
        The command, writing ``out``.
    out : pathlib.Path
        Its output.
    timeout : float
        Seconds each may take.

    Returns
    -------
    dict
        The case's outcome with its class.
    """
    cmd = [sys.executable, "-m", "hystid", *argv]
    first = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             text=True)
    time.sleep(1.0)
    second = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True)
    try:  # two runs share the cores: each gets three timeouts
        r1 = first.communicate(timeout=3 * timeout)
        r2 = second.communicate(timeout=3 * timeout)
    except subprocess.TimeoutExpired:
        first.kill()
        second.kill()
        return {"class": "hang", "status": None, "stderr": ""}
    codes = (first.returncode, second.returncode)
    errs = r1[1] + r2[1]
    if "Traceback" in errs:
        cls = "traceback"
    elif sorted(codes) == [0, 2]:
        cls = "clear-error"
    elif codes == (0, 0):
        cls = "overwrite"
    else:
        cls = "traceback"
    return {"class": cls, "status": list(codes), "stderr": errs[-2000:]}


def intruder(work: Path, rec: Path, timeout: float) -> dict:
    """A file written into ``--out`` while ``identify`` runs must survive (no ``--force``).

    Parameters
    ----------
    work : pathlib.Path
        Scratch folder.
    rec : pathlib.Path
        A record.
    timeout : float
        Seconds the run may take.

    Returns
    -------
    dict
        The case's outcome with its class.
    """
    out = work / "intruded"
    proc = subprocess.Popen([sys.executable, "-m", "hystid", "identify", str(rec), "--out",
                             str(out)], cwd=ROOT, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.time() + timeout
    while time.time() < deadline and proc.poll() is None:
        if out.exists() or time.time() > deadline - timeout + 1.5:
            break
        time.sleep(0.05)
    out.mkdir(exist_ok=True)
    (out / "report.json").write_text("mine\n")
    try:
        _, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        return {"class": "hang", "status": None, "stderr": ""}
    kept = (out / "report.json").read_text() == "mine\n"
    if "Traceback" in err:
        cls = "traceback"
    elif not kept:
        cls = "overwrite"
    elif proc.returncode == 2:
        cls = "clear-error"
    else:
        cls = "sound"  # finished before the intruder wrote (then the intruder's file is kept)
    return {"class": cls, "status": proc.returncode, "stderr": err[-2000:]}


# --------------------------------------------------------------------------- main
def main(argv: list[str] | None = None) -> int:
    """Run the audit; print the table and the counts; write JSON.

    Parameters
    ----------
    argv : list of str, optional
        Command-line arguments.

    Returns
    -------
    int
        0 when no case is a traceback, hang, silent wrong result or overwrite; else 1.
    """
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=None, help="JSON file of the results")
    parser.add_argument("--timeout", type=float, default=60.0, help="seconds per case")
    parser.add_argument("--only", default=None, help="run the cases whose name has this word")
    parser.add_argument("--no-big", action="store_true", help="leave out the 1e7-sample records")
    args = parser.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory(prefix="hystid-audit-") as tmp:
        work = Path(tmp)
        cases = build_cases(work, big=not args.no_big)
        for case in cases:
            if args.only and args.only not in case.name:
                continue
            res = run(case.argv, args.timeout, api=case.api)
            res["class"] = classify(case, res)
            rows.append({"case": case.name, **res})
            print(f"{res['class']:13s} {res['seconds']:7.1f} s  {case.name}", flush=True)
        rec = work / "rec.csv"
        races = [
            ("race identify --out", ["identify", str(rec), "--quiet", "--out",
                                     str(work / "race_rep")], work / "race_rep"),
            ("race simulate --out", ["simulate", "--seconds", "2", "--seed", "0", "--quiet",
                                     "--out", str(work / "race.csv")], work / "race.csv"),
            ("race fleet --out", ["fleet", "identify", str(rec), "--workers", "1", "--quiet",
                                  "--out", str(work / "race_fleet")], work / "race_fleet"),
        ]
        for name, cmd, out in races:
            if args.only and args.only not in name:
                continue
            res = race(work, name, cmd, out, args.timeout)
            rows.append({"case": name, **res})
            print(f"{res['class']:13s} {'':9s}  {name}", flush=True)
        if not args.only or args.only in "intruder in --out":
            res = intruder(work, rec, args.timeout)
            rows.append({"case": "intruder in --out", **res})
            print(f"{res['class']:13s} {'':9s}  intruder in --out", flush=True)
    counts = Counter(r["class"] for r in rows)
    print("\n" + ", ".join(f"{c}: {counts.get(c, 0)}" for c in CLASSES) + f" ({len(rows)} cases)")
    for r in rows:
        if r["class"] in ("traceback", "hang", "silent-wrong", "overwrite"):
            tail = r.get("stderr", "").strip().splitlines()[-1:] or [""]
            print(f"  {r['class']}: {r['case']}: {tail[0][:200]}")
    if args.out:
        Path(args.out).write_text(json.dumps({"counts": {c: counts.get(c, 0) for c in CLASSES},
                                              "cases": rows}, indent=1))
    bad = sum(counts.get(c, 0) for c in ("traceback", "hang", "silent-wrong", "overwrite"))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
