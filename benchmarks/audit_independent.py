"""An independent hostile-input audit of hystid: the command line and the public Python API.

Written from the README, the commands' ``--help`` and the public API alone (not from the
project's own audit). It generates hostile cases of its own design, runs each one (a command in
its own process group, an API call in a forked child) with a timeout, and classifies it:

* ``clear-error``: refused with a one-line message (status 2 on the command line; a
  ``ValueError``, ``TypeError`` or ``OSError`` naming the file or option from Python);
* ``sound-result``: done, and the result is right, or doubtful and said so;
* ``traceback``: a Python traceback on stderr, a crash, or from Python an exception of another
  kind (or one whose message names neither the file nor the option);
* ``hang``: not done within ``--timeout`` seconds;
* ``silent-wrong``: done without a word, yet wrong (a model identified from swapped columns or
  pure noise presented as good, a result that changes when only the input offset or the units
  change, a bad value accepted as if it were data);
* ``overwrite``: a file the user had was replaced or removed without ``--force`` (or an input
  file destroyed even with it), or two runs writing one output both said they succeeded.

Usage::

    OPENBLAS_NUM_THREADS=1 python audit_independent.py --out /tmp/audit_ind.json
    python audit_independent.py --quick            # a subset of about a third
    python audit_independent.py --only model_file  # the cases whose name holds this text

Every random signal comes from a seeded generator; the records are short (0.2 s at 30 kHz) so
that a full run takes some ten minutes on two shared cores. The workspace is a temporary
folder (``--keep DIR`` keeps it). Run as root, ``chmod`` cannot make a path read-only, so the
read-only cases write under ``/proc``.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import math
import multiprocessing
import os
import re
import shutil
import signal
import stat
import struct
import subprocess
import sys
import tempfile
import time
import traceback
import warnings
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

# The hystid audited is the one of the source tree this script lives in (its commands run with
# that tree first on PYTHONPATH), not whatever copy the environment has installed.
ROOT = Path(__file__).resolve().parents[1]
if (ROOT / "hystid" / "__init__.py").is_file():
    sys.path.insert(0, str(ROOT))
    os.environ["PYTHONPATH"] = os.pathsep.join(
        [str(ROOT), *filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))])
HYSTID = str(Path(sys.executable).with_name("hystid"))
CLASSES = ("clear-error", "sound-result", "traceback", "hang", "silent-wrong", "overwrite")
BAD = ("traceback", "hang", "silent-wrong", "overwrite")
FS = 30_000.0
SECONDS = 0.2
TRACEBACK = "Traceback (most recent call last)"


# =========================================================================== the cases
@dataclass
class Outcome:
    """What one run did: status, output, time, whether it timed out."""

    status: int | None
    stdout: str
    stderr: str
    seconds: float
    hung: bool


@dataclass
class Case:
    """One hostile case.

    ``kind`` is ``cli`` (``argv`` for ``hystid``), ``api`` (``call(ws)`` in a forked child,
    returning a summary) or ``custom`` (``call(ws, timeout)`` returning a finished row).
    ``setup(ws)`` writes the case's files; ``replaceable`` are files the case lets a ``--force``
    replace; ``judge(ws, outcome_or_value)`` says whether a success is sound.
    """

    name: str
    group: str
    kind: str
    argv: list[str] | None = None
    call: Callable[..., Any] | None = None
    setup: Callable[[Path], None] | None = None
    expect: str = "error"  # "error": a success must say why it accepted; "ok"; "any"
    hints: tuple[str, ...] = ()
    judge: Callable[[Path, Any], tuple[str, str]] | None = None
    replaceable: tuple[str, ...] = ()
    quick: bool = False
    timeout: float | None = None
    what: str = ""


CASES: list[Case] = []


def cli(name: str, argv: list[str], group: str, **kw: Any) -> None:
    """Register a command-line case (``argv`` after ``hystid``)."""
    CASES.append(Case(name=name, group=group, kind="cli", argv=argv, **kw))


def api(name: str, call: Callable[[Path], Any], group: str, **kw: Any) -> None:
    """Register an API case: ``call(ws)`` runs in a forked child."""
    CASES.append(Case(name=name, group=group, kind="api", call=call, **kw))


def custom(name: str, call: Callable[[Path, float], dict], group: str, **kw: Any) -> None:
    """Register a case that runs several commands itself and classifies them."""
    CASES.append(Case(name=name, group=group, kind="custom", call=call, **kw))


# =========================================================================== base data
class Base:
    """The audit's base records and models, made once per run (seeded)."""

    dir: Path
    t: np.ndarray
    u: np.ndarray
    y: np.ndarray
    uv: np.ndarray
    yv: np.ndarray
    rms: float  # held-out RMS of the base identification (CLI, defaults)
    pred: np.ndarray  # base model's prediction on the validation input
    span: float


BASE = Base()


def make_base(root: Path) -> None:
    """Simulate the reference stage (seeds 0 and 1), write the base files, identify once."""
    from hystid.identify import identify
    from hystid.modelfile import load_model, save_model
    from hystid.reference import reference_record

    BASE.dir = root / "_base"
    BASE.dir.mkdir(parents=True)
    tr = reference_record(SECONDS, seed=0)
    va = reference_record(SECONDS, seed=1)
    BASE.t, BASE.u, BASE.y = np.arange(tr.n) / FS, tr.u.copy(), tr.y.copy()
    BASE.uv, BASE.yv = va.u.copy(), va.y.copy()
    write_csv(BASE.dir / "train.csv", BASE.t, BASE.u, BASE.y)
    write_csv(BASE.dir / "val.csv", BASE.t, BASE.uv, BASE.yv)
    out = run([*"identify train.csv --val val.csv --json --quiet --out rep".split()],
              BASE.dir, 300)
    if out.status != 0:
        raise SystemExit(f"the base identification failed:\n{out.stderr}")
    report = json.loads(out.stdout)
    BASE.rms = float(report["validation"]["rms"])
    shutil.copy(BASE.dir / "rep" / "model.json", BASE.dir / "model.json")
    model = load_model(BASE.dir / "model.json")
    BASE.pred = simulate_quiet(model, BASE.uv)
    BASE.span = float(np.ptp(BASE.yv))
    for member in ("pi-stage", "pi", "mduhem", "pi-poly"):
        res = identify(tr, model=member)
        save_model(res.model, BASE.dir / f"{member}.json")
    # numba compiles a kernel the first time a tree runs it (a minute or more): run each
    # command once here, so that no case pays for it against its timeout
    for argv in (["demo", "--seconds", "0.1", "--out", "warm-demo", "--quiet"],
                 ["identify", "train.csv", "--model", "pi-stage", "--method", "online",
                  "--quiet", "--out", "warm-pi"],
                 ["diagnose", "train.csv", "--val", "val.csv", "--time-budget", "0",
                  "--quiet", "--out", "warm-diag"],
                 ["compensate", "model.json", "--scan", "triangle:50:2", "--out", "warm.csv",
                  "--quiet"],
                 ["export", "model.json", "--c", "warm-c", "--quiet"]):
        run(argv, BASE.dir, 900)


def simulate_quiet(model: Any, u: np.ndarray) -> np.ndarray:
    """A model's output on ``u`` without admissibility warnings."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return np.asarray(model.simulate(np.asarray(u, float), check=False).y, float)


# =========================================================================== file writers
def write_csv(path: Path, t: np.ndarray | None, u: np.ndarray, y: np.ndarray, *,
              header: str | None = "t,u,y", sep: str = ",", newline: str = "\n",
              fmt: str = "%.12g", prefix: str = "", encoding: str = "utf-8") -> None:
    """A delimited text record."""
    cols = [u, y] if t is None else [t, u, y]
    if header is not None and t is None and header == "t,u,y":
        header = "u,y"
    lines = [] if header is None else [header.replace(",", sep)]
    for row in zip(*cols, strict=True):
        lines.append(sep.join(fmt % v for v in row))
    Path(path).write_bytes((prefix + newline.join(lines) + newline).encode(encoding))


def base_rows(n: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The base training record's first ``n`` samples."""
    n = len(BASE.u) if n is None else n
    return BASE.t[:n].copy(), BASE.u[:n].copy(), BASE.y[:n].copy()


def text_file(name: str, text: str | bytes) -> Callable[[Path], None]:
    """A setup writing one file."""
    def setup(ws: Path) -> None:
        data = text.encode() if isinstance(text, str) else text
        (ws / name).write_bytes(data)
    return setup


def csv_variant(name: str, **kw: Any) -> Callable[[Path], None]:
    """A setup writing the base training record with another CSV layout."""
    def setup(ws: Path) -> None:
        t, u, y = base_rows()
        write_csv(ws / name, t, u, y, **kw)
    return setup


def csv_rows(name: str, edit: Callable[[list[str]], list[str]], header: str = "t,u,y"
             ) -> Callable[[Path], None]:
    """A setup writing the base record's lines after ``edit`` (of the data lines)."""
    def setup(ws: Path) -> None:
        t, u, y = base_rows()
        lines = [f"{a:.12g},{b:.12g},{c:.12g}" for a, b, c in zip(t, u, y, strict=True)]
        (ws / name).write_text("\n".join([header, *edit(lines)]) + "\n")
    return setup


def csv_arrays(name: str, make: Callable[[], tuple[Any, Any, Any]], **kw: Any
               ) -> Callable[[Path], None]:
    """A setup writing the arrays ``make()`` returns (``t`` may be ``None``)."""
    def setup(ws: Path) -> None:
        t, u, y = make()
        write_csv(ws / name, t, np.asarray(u), np.asarray(y), **kw)
    return setup


def npz_file(name: str, make: Callable[[], dict[str, Any]]) -> Callable[[Path], None]:
    """A setup writing ``np.savez(name, **make())``."""
    def setup(ws: Path) -> None:
        with open(ws / name, "wb") as fh:
            np.savez(fh, **make())
    return setup


def mat_file(name: str, make: Callable[[], dict[str, Any]]) -> Callable[[Path], None]:
    """A setup writing a MATLAB 5 file with scipy."""
    def setup(ws: Path) -> None:
        from scipy.io import savemat
        savemat(ws / name, make())
    return setup


def h5_file(name: str, fill: Callable[[Any], None]) -> Callable[[Path], None]:
    """A setup writing an HDF5 file through ``fill(h5py.File)``."""
    def setup(ws: Path) -> None:
        import h5py
        with h5py.File(ws / name, "w") as fh:
            fill(fh)
    return setup


def plain_arrays() -> dict[str, Any]:
    """The base record as arrays u, y, fs."""
    return {"u": BASE.u.copy(), "y": BASE.y.copy(), "fs": np.float64(FS)}


def truncated(name: str, setup: Callable[[Path], None], keep: float) -> Callable[[Path], None]:
    """A setup writing a file with ``setup`` and keeping only its first ``keep`` share."""
    def run_setup(ws: Path) -> None:
        setup(ws)
        data = (ws / name).read_bytes()
        (ws / name).write_bytes(data[: int(len(data) * keep)])
    return run_setup


def both(*setups: Callable[[Path], None]) -> Callable[[Path], None]:
    """Run several setups in turn."""
    def setup(ws: Path) -> None:
        for s in setups:
            s(ws)
    return setup


def copy_base(*names: str) -> Callable[[Path], None]:
    """A setup copying base files (``train.csv``, ``val.csv``, ``model.json``, ...)."""
    def setup(ws: Path) -> None:
        for n in names:
            shutil.copy(BASE.dir / n, ws / n)
    return setup


def fifo(name: str) -> Callable[[Path], None]:
    """A setup making a named pipe nobody writes to."""
    return lambda ws: os.mkfifo(ws / name)


def symlink(name: str, target: str) -> Callable[[Path], None]:
    """A setup making a symbolic link."""
    return lambda ws: os.symlink(target, ws / name)


def model_doc(edit: Callable[[dict], Any] | None = None, source: str = "model.json",
              name: str = "m.json", raw: Callable[[str], str] | None = None
              ) -> Callable[[Path], None]:
    """A setup writing a base model file after ``edit`` of its JSON (or ``raw`` of its text)."""
    def setup(ws: Path) -> None:
        text = (BASE.dir / source).read_text()
        if edit is not None:
            doc = json.loads(text)
            new = edit(doc)
            doc = doc if new is None else new
            text = json.dumps(doc, allow_nan=True)
        if raw is not None:
            text = raw(text)
        (ws / name).write_text(text)
        if not (ws / "train.csv").exists():
            shutil.copy(BASE.dir / "train.csv", ws / "train.csv")
    return setup


def setp(path: str, value: Any) -> Callable[[dict], None]:
    """An edit setting ``doc[a][b]...`` (``path`` dotted) to ``value``."""
    def edit(doc: dict) -> None:
        keys = path.split(".")
        node = doc
        for k in keys[:-1]:
            node = node[k]
        node[keys[-1]] = value
    return edit


def delp(path: str) -> Callable[[dict], None]:
    """An edit removing ``doc[a][b]...``."""
    def edit(doc: dict) -> None:
        keys = path.split(".")
        node = doc
        for k in keys[:-1]:
            node = node[k]
        del node[keys[-1]]
    return edit


# =========================================================================== running
def run(argv: list[str], cwd: Path, timeout: float) -> Outcome:
    """Run ``hystid argv`` in ``cwd`` in its own process group, killed after ``timeout``."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([HYSTID, *argv], cwd=cwd, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, stdin=subprocess.DEVNULL,
                            start_new_session=True)
    return finish(proc, t0, timeout)


def start(argv: list[str], cwd: Path) -> tuple[subprocess.Popen, float]:
    """Start ``hystid argv`` in the background."""
    proc = subprocess.Popen([HYSTID, *argv], cwd=cwd, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, stdin=subprocess.DEVNULL,
                            start_new_session=True)
    return proc, time.perf_counter()


def finish(proc: subprocess.Popen, t0: float, timeout: float) -> Outcome:
    """Wait for a started command; kill its process group (only it) when it overruns."""
    try:
        out, err = proc.communicate(timeout=max(0.1, timeout - (time.perf_counter() - t0)))
        hung = False
    except subprocess.TimeoutExpired:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        hung = True
    return Outcome(None if hung else proc.returncode, out.decode("utf-8", "replace"),
                   err.decode("utf-8", "replace"), time.perf_counter() - t0, hung)


def snapshot(ws: Path) -> dict[str, str]:
    """Every file under ``ws`` (not following links) and a digest of its bytes."""
    found: dict[str, str] = {}
    for root, dirs, files in os.walk(ws):
        for name in files + [d for d in dirs if os.path.islink(os.path.join(root, d))]:
            p = os.path.join(root, name)
            rel = os.path.relpath(p, ws)
            st = os.lstat(p)
            if stat.S_ISREG(st.st_mode):
                with open(p, "rb") as fh:
                    found[rel] = hashlib.sha256(fh.read()).hexdigest()
            else:
                link = os.readlink(p) if os.path.islink(p) else ""
                found[rel] = f"special:{stat.S_IFMT(st.st_mode)}:{link}"
    return found


def changed_files(before: dict[str, str], ws: Path) -> list[str]:
    """The files of ``before`` that are gone or hold other bytes now."""
    after = snapshot(ws)
    return [f for f, digest in before.items() if after.get(f) != digest]


def error_line(stderr: str) -> str:
    """The line of stderr that says the error (the last one holding 'error')."""
    lines = [ln for ln in stderr.strip().splitlines() if "error" in ln.lower()]
    return lines[-1] if lines else (stderr.strip().splitlines() or [""])[-1]


def warned(text: str) -> bool:
    """Whether a command's output holds one of hystid's own warning lines
    (``hystid COMMAND: warning: ...``) or is a JSON report with a non-empty ``warnings`` list.
    A Python warning that leaks from a library (``RuntimeWarning: overflow ...``) is not a
    warning addressed to the user and does not count."""
    with contextlib.suppress(ValueError):
        doc = json.loads(text)
        return isinstance(doc, dict) and bool(report_warnings(doc))
    return any(ln.startswith("hystid") and ": warning:" in ln for ln in text.splitlines())


def classify_cli(case: Case, ws: Path, out: Outcome, changed: list[str]) -> tuple[str, str]:
    """The class of a finished command and a note."""
    forced = "--force" in (case.argv or [])
    lost = [f for f in changed if not (forced and f in case.replaceable)]
    if out.hung:
        return "hang", f"not done in {out.seconds:.0f} s"
    if TRACEBACK in out.stderr:
        last = out.stderr.strip().splitlines()[-1]
        return "traceback", last[:200]
    if lost:
        return "overwrite", "changed or removed: " + ", ".join(lost[:5])
    if out.status is not None and out.status < 0:
        return "traceback", f"killed by signal {-out.status}"
    if out.status == 0:
        if case.judge is not None:
            return case.judge(ws, out)
        if case.expect == "error":
            if warned(out.stderr) or warned(out.stdout[:4000]):
                return "sound-result", "accepted with a warning: " + first_warning(out)
            return "silent-wrong", "accepted without a word"
        return "sound-result", ""
    line = error_line(out.stderr)
    note = line[:240]
    if case.hints and not any(h.lower() in line.lower() for h in case.hints):
        note = "[vague] " + note
    if out.status != 2:
        note = f"[status {out.status}] " + note
    if case.expect == "ok":
        note = "[refused a sound input] " + note
    return "clear-error", note


def first_warning(out: Outcome) -> str:
    """The first of hystid's own warning lines of a command."""
    for ln in (out.stderr + "\n" + out.stdout[:4000]).splitlines():
        if ln.startswith("hystid") and ": warning:" in ln:
            return ln.strip()[:200]
    return ""


# --------------------------------------------------------------------------- API children
def _child(call: Callable[[Path], Any], ws: Path, conn: Any) -> None:
    """Run an API call and send a summary of what happened."""
    os.chdir(ws)
    caught: list[str] = []
    try:
        with warnings.catch_warnings(record=True) as wlist:
            warnings.simplefilter("always")
            value = call(ws)
            caught = [f"{w.category.__name__}: {w.message}" for w in wlist]
        conn.send({"ok": True, "value": value, "warnings": caught})
    except BaseException as err:  # noqa: BLE001 - the audit reports whatever escaped
        conn.send({"ok": False, "type": type(err).__name__,
                   "mro": [c.__name__ for c in type(err).__mro__],
                   "message": str(err)[:600],
                   "where": traceback.format_exc().strip().splitlines()[-3:]})
    finally:
        conn.close()


def run_api(case: Case, ws: Path, timeout: float) -> tuple[Outcome, dict | None]:
    """Run an API case in a forked child, killed after ``timeout``."""
    ctx = multiprocessing.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    t0 = time.perf_counter()
    proc = ctx.Process(target=_child, args=(case.call, ws, child))
    proc.start()
    child.close()
    result = None
    if parent.poll(timeout):
        with contextlib.suppress(EOFError):
            result = parent.recv()
    proc.join(max(0.1, timeout - (time.perf_counter() - t0)))
    hung = result is None and proc.is_alive()
    if proc.is_alive():
        proc.kill()
        proc.join()
    return Outcome(proc.exitcode, "", "", time.perf_counter() - t0, hung), result


def classify_api(case: Case, ws: Path, out: Outcome, result: dict | None) -> tuple[str, str]:
    """The class of an API case."""
    if out.hung:
        return "hang", f"not done in {out.seconds:.0f} s"
    if result is None:
        return "traceback", f"the child died (exit code {out.status})"
    if not result["ok"]:
        clear = {"ValueError", "TypeError", "OSError"} & set(result["mro"])
        msg = result["message"]
        named = not case.hints or any(h.lower() in msg.lower() for h in case.hints)
        note = f"{result['type']}: {msg}"[:240]
        if not clear:
            return "traceback", note
        if not msg.strip() or not named:
            return "traceback", "[names neither file nor option] " + note
        if case.expect == "ok":
            note = "[refused a sound input] " + note
        return "clear-error", note
    if case.judge is not None:
        return case.judge(ws, result)
    if case.expect == "error":
        if result["warnings"]:
            return "sound-result", "accepted with a warning: " + result["warnings"][0][:200]
        return "silent-wrong", "accepted without a word: " + str(result["value"])[:150]
    return "sound-result", str(result["value"])[:150]


# =========================================================================== judges
def report_of(ws: Path, out: Outcome, folder: str = "rep") -> dict:
    """The identification report: ``--json`` on stdout, else ``folder/report.json``."""
    with contextlib.suppress(ValueError):
        return json.loads(out.stdout)
    with contextlib.suppress(OSError, ValueError):
        return json.loads((ws / folder / "report.json").read_text())
    return {}


def report_warnings(rep: dict) -> list[str]:
    """Every warning a report carries."""
    found = list(rep.get("warnings") or [])
    found += list((rep.get("info") or {}).get("warnings") or [])
    return [str(w) for w in found]


def presented_as_good(rep: dict, out: Outcome) -> bool:
    """A report that beats its baselines and says no warning at all."""
    return bool(rep.get("beats_baselines")) and not report_warnings(rep) and \
        not warned(out.stderr)


def model_from(ws: Path, folder: str = "rep") -> Any:
    """The model a case's run wrote."""
    from hystid.modelfile import load_model
    return load_model(ws / folder / "model.json")


def judge_fit(tol: float = 3.0, need_warning: bool = False) -> Callable:
    """Sound when the held-out RMS is within ``tol`` x the base's (in the base's units), or a
    warning says why not; ``need_warning``: the data was damaged, a success must say so."""
    def judge(ws: Path, out: Outcome) -> tuple[str, str]:
        rep = report_of(ws, out)
        rms = (rep.get("validation") or {}).get("rms")
        w = report_warnings(rep) + ([first_warning(out)] if warned(out.stderr) else [])
        note = f"held-out RMS {rms:.3g} (base {BASE.rms:.3g})" if rms is not None else "no RMS"
        if need_warning and not w:
            return "silent-wrong", "damaged data accepted without a word; " + note
        if rms is None:
            return "sound-result", note
        if rms <= tol * BASE.rms or w or not rep.get("beats_baselines", True):
            return "sound-result", note + ("; warned: " + w[0][:120] if w else "")
        return "silent-wrong", note + ", presented as good"
    return judge


def judge_suspect(why: str) -> Callable:
    """The data cannot give a trustworthy model: a success must warn or not beat baselines."""
    def judge(ws: Path, out: Outcome) -> tuple[str, str]:
        rep = report_of(ws, out)
        rms = (rep.get("validation") or {}).get("rms")
        if presented_as_good(rep, out):
            return "silent-wrong", f"{why}: identified and presented as good (held-out RMS " \
                                   f"{rms}, beats baselines, no warning)"
        w = report_warnings(rep) + ([first_warning(out)] if warned(out.stderr) else [])
        return "sound-result", (w[0][:160] if w else "does not beat its baselines")
    return judge


def judge_same(transform_u: Callable[[np.ndarray], np.ndarray],
               back_y: Callable[[np.ndarray], np.ndarray], what: str,
               rel: float = 0.25) -> Callable:
    """The model must predict the base model's output on the (transformed) validation input:
    prediction differences of more than ``rel`` x the base held-out RMS are a changed result."""
    def judge(ws: Path, out: Outcome) -> tuple[str, str]:
        try:
            model = model_from(ws)
        except Exception as err:  # noqa: BLE001
            return "silent-wrong", f"no readable model ({err})"
        pred = back_y(simulate_quiet(model, transform_u(BASE.uv)))
        # both zeroed at their first sample: a sensor offset is free
        d = (pred - pred[0]) - (BASE.pred - BASE.pred[0])
        diff = float(np.sqrt(np.mean(d ** 2))) if np.all(np.isfinite(d)) else math.inf
        note = f"{what}: prediction differs from the base model's by {diff:.3g} RMS " \
               f"(base held-out RMS {BASE.rms:.3g})"
        if diff > rel * BASE.rms:
            return "silent-wrong", note
        return "sound-result", note
    return judge


def judge_file_ok(name: str) -> Callable:
    """Sound when the output file exists and loads as a record."""
    def judge(ws: Path, out: Outcome) -> tuple[str, str]:
        from hystid.records import load_record
        try:
            rec = load_record(ws / name)
        except Exception as err:  # noqa: BLE001
            return "silent-wrong", f"status 0 but {name} does not load: {err}"[:240]
        if not (np.all(np.isfinite(rec.u)) and np.all(np.isfinite(rec.y))):
            return "silent-wrong", f"{name} holds non-finite values"
        return "sound-result", f"{name}: {rec.n} samples"
    return judge


def judge_sim_output(name: str, limit: float = 1e6) -> Callable:
    """A simulated output of a doubtful model: huge or non-finite values need a warning."""
    def judge(ws: Path, out: Outcome) -> tuple[str, str]:
        from hystid.records import load_record
        try:
            rec = load_record(ws / name)
        except Exception as err:  # noqa: BLE001
            return "silent-wrong", f"status 0 but {name} does not load: {err}"[:240]
        peak = float(np.max(np.abs(rec.y)))
        if (not np.isfinite(peak) or peak > limit) and not warned(out.stderr):
            return "silent-wrong", f"output peaks at {peak:.3g} without a word"
        if warned(out.stderr):
            return "sound-result", f"peak {peak:.3g}; " + first_warning(out)
        return "sound-result", f"peak {peak:.3g}"
    return judge


def judge_api_value(check: Callable[[Any], str | None]) -> Callable:
    """An API success: ``check(value)`` returns a reason it is wrong, or None."""
    def judge(ws: Path, result: dict) -> tuple[str, str]:
        why = check(result["value"])
        if why and not result["warnings"]:
            return "silent-wrong", why
        if why:
            return "sound-result", why + "; warned: " + result["warnings"][0][:120]
        return "sound-result", str(result["value"])[:160]
    return judge


# =========================================================================== case catalogue
ID = ["identify"]
IDQ = ["--json", "--quiet", "--out", "rep"]


def add_record_file_cases() -> None:
    """Malformed and odd record files, through ``hystid identify``."""
    g = "record_file"

    def idc(name: str, file: str, setup: Callable, extra: list[str] | None = None, **kw: Any
            ) -> None:
        kw.setdefault("hints", (file,))
        cli(name, [*ID, file, *(extra or []), *IDQ], g, setup=setup, **kw)

    idc("csv_plain", "r.csv", csv_variant("r.csv"), expect="ok", judge=judge_fit(), quick=True)
    idc("csv_semicolon", "r.csv", csv_variant("r.csv", sep=";"), expect="any",
        judge=judge_fit(), quick=True)
    idc("csv_tab_txt", "r.txt", csv_variant("r.txt", sep="\t"), expect="any", judge=judge_fit())
    idc("csv_spaces", "r.txt", csv_variant("r.txt", sep="   "), expect="any", judge=judge_fit())
    idc("csv_decimal_comma", "r.csv", csv_rows(
        "r.csv", lambda ls: [ln.replace(",", ";").replace(".", ",") for ln in ls],
        header="t;u;y"), expect="any", judge=judge_fit(), quick=True,
        what="European CSV: ';' between fields, ',' as the decimal mark")
    idc("csv_bom", "r.csv", csv_variant("r.csv", prefix="\ufeff"), expect="any",
        judge=judge_fit(), quick=True)
    idc("csv_crlf", "r.csv", csv_variant("r.csv", newline="\r\n"), expect="any",
        judge=judge_fit())
    idc("csv_cr_only", "r.csv", csv_variant("r.csv", newline="\r"), expect="any",
        judge=judge_fit())
    idc("csv_utf16", "r.csv", csv_variant("r.csv", encoding="utf-16"), expect="any",
        judge=judge_fit())
    idc("csv_comment_lines", "r.csv", csv_rows(
        "r.csv", lambda ls: ["# exported by scope 1.2", *ls[:3000], "# pause", *ls[3000:]]),
        expect="any", judge=judge_fit())
    idc("csv_inline_comment", "r.csv", csv_rows(
        "r.csv", lambda ls: [ln + "  # ok" if i % 500 == 0 else ln for i, ln in enumerate(ls)]),
        expect="any", judge=judge_fit())
    idc("csv_blank_lines", "r.csv", csv_rows(
        "r.csv", lambda ls: [*ls[:2000], "", "   ", *ls[2000:]]), expect="any",
        judge=judge_fit())
    idc("csv_quoted", "r.csv", csv_rows(
        "r.csv", lambda ls: ['"' + ln.replace(",", '","') + '"' for ln in ls],
        header='"t","u","y"'), expect="any", judge=judge_fit())
    idc("csv_extra_columns", "r.csv", csv_rows(
        "r.csv", lambda ls: [ln + ",21.5,ok" for ln in ls], header="t,u,y,temp,flag"),
        expect="any", judge=judge_fit())
    idc("csv_trailing_delimiter", "r.csv", csv_rows(
        "r.csv", lambda ls: [ln + "," for ln in ls], header="t,u,y,"), expect="any",
        judge=judge_fit())
    idc("csv_units_row", "r.csv", csv_rows(
        "r.csv", lambda ls: ["s,V,um", *ls]), expect="any", judge=judge_fit())
    idc("csv_header_upper", "r.csv", csv_rows("r.csv", lambda ls: ls, header="T,U,Y"),
        expect="any", judge=judge_fit())
    idc("csv_duplicate_header", "r.csv", csv_rows(
        "r.csv", lambda ls: [ln + ",0" for ln in ls], header="t,u,y,u"), quick=True)
    idc("csv_missing_cell", "r.csv", csv_rows(
        "r.csv", lambda ls: [*ls[:100], ls[100].rsplit(",", 1)[0] + ",", *ls[101:]]),
        quick=True)
    idc("csv_short_row", "r.csv", csv_rows(
        "r.csv", lambda ls: [*ls[:100], ls[100].rsplit(",", 1)[0], *ls[101:]]))
    idc("csv_nan_y", "r.csv", csv_rows(
        "r.csv", lambda ls: [*ls[:100], ls[100].rsplit(",", 1)[0] + ",nan", *ls[101:]]),
        quick=True)
    idc("csv_inf_u", "r.csv", csv_rows(
        "r.csv", lambda ls: [*ls[:100], "{},inf,{}".format(ls[100].split(",")[0],
                                                       ls[100].split(",")[2]), *ls[101:]]))
    idc("csv_overflow_1e999", "r.csv", csv_rows(
        "r.csv", lambda ls: [*ls[:100], ls[100].rsplit(",", 1)[0] + ",1e999", *ls[101:]]))
    idc("csv_integer_overflow_string", "r.csv", csv_rows(
        "r.csv", lambda ls: [*ls[:3000], "{},{},{}".format(ls[3000].split(",")[0],
                                                       "9" * 40, ls[3000].split(",")[2]),
                             *ls[3001:]]),
        judge=judge_fit(need_warning=True), what="one input sample 9999...9 (40 digits)")
    idc("csv_text_cell", "r.csv", csv_rows(
        "r.csv", lambda ls: [*ls[:50], ls[50].rsplit(",", 1)[0] + ",ERR", *ls[51:]]))
    idc("csv_fortran_exponent", "r.csv", csv_rows(
        "r.csv", lambda ls: [ln.replace("e", "D") for ln in ls]), expect="any",
        judge=judge_fit())
    idc("csv_timestamps", "r.csv", csv_rows(
        "r.csv", lambda ls: ["2024-01-01 00:00:{:09.6f},{}".format(i / FS, ln.split(",", 1)[1])
                             for i, ln in enumerate(ls)]))
    idc("csv_nul_bytes", "r.csv", both(csv_variant("r.csv"),
                                       lambda ws: (ws / "r.csv").write_bytes(
                                           (ws / "r.csv").read_bytes()[:5000] + b"\0" * 64
                                           + (ws / "r.csv").read_bytes()[5000:])))
    cli("csv_latin1_header", [*ID, "r.csv", *IDQ], g, expect="any", judge=judge_fit(),
        setup=lambda ws: (ws / "r.csv").write_bytes(
            "# Messung \xb5m, Spannung\n".encode("latin-1") +
            (BASE.dir / "train.csv").read_bytes().split(b"\n", 1)[1]), hints=("r.csv",))
    idc("csv_empty", "r.csv", text_file("r.csv", ""), quick=True)
    idc("csv_header_only", "r.csv", text_file("r.csv", "t,u,y\n"))
    idc("csv_bom_header_only", "r.csv", text_file("r.csv", "\ufefft,u,y\r\n"))
    idc("csv_one_sample", "r.csv", text_file("r.csv", "t,u,y\n0,1,2\n"), quick=True)
    idc("csv_two_samples", "r.csv", text_file("r.csv", "t,u,y\n0,1,2\n1e-4,2,3\n"))
    idc("csv_ten_samples", "r.csv", csv_arrays("r.csv", lambda: base_rows(10)))
    idc("csv_binary_garbage", "r.csv", text_file(
        "r.csv", np.random.default_rng(3).integers(0, 256, 50_000, dtype=np.uint8).tobytes()))
    idc("csv_duplicated_time", "r.csv", csv_rows(
        "r.csv", lambda ls: [*ls[:1000], ls[1000], *ls[1000:]]), quick=True)
    idc("csv_unsorted_time", "r.csv", csv_rows(
        "r.csv", lambda ls: [*ls[:1000], ls[1001], ls[1000], *ls[1002:]]))
    idc("csv_reversed_time", "r.csv", csv_rows("r.csv", lambda ls: ls[::-1]))

    def jitter() -> tuple:
        t, u, y = base_rows()
        rng = np.random.default_rng(5)
        return t + rng.uniform(-0.3, 0.3, t.size) / FS, u, y
    idc("csv_jittered_time", "r.csv", csv_arrays("r.csv", jitter), quick=True)

    def gap() -> tuple:
        t, u, y = base_rows()
        keep = np.r_[0:2500, 2800:t.size]
        return t[keep], u[keep], y[keep]
    idc("csv_time_gap", "r.csv", csv_arrays("r.csv", gap))

    def epoch() -> tuple:
        t, u, y = base_rows()
        return t + 1.7e9, u, y
    idc("csv_epoch_time", "r.csv", csv_arrays("r.csv", epoch, fmt="%.17g"), expect="any",
        judge=judge_fit(), what="t in Unix seconds: 1.7e9 + k/30000")
    idc("csv_constant_time", "r.csv", csv_arrays(
        "r.csv", lambda: (np.zeros(6000), BASE.u, BASE.y)))
    idc("csv_huge_time", "r.csv", csv_arrays(
        "r.csv", lambda: (np.arange(6000) * 1e300, BASE.u, BASE.y)), expect="any",
        what="t in steps of 1e300 s: a rate of 1e-300 Hz, absurd but consistent")
    idc("csv_no_header", "r.csv", csv_variant("r.csv", header=None))
    cli("csv_no_header_positions", [*ID, "r.csv", "--columns", "t=0,u=1,y=2", *IDQ], g,
        setup=csv_variant("r.csv", header=None), expect="ok", judge=judge_fit())
    cli("csv_columns_out_of_range", [*ID, "r.csv", "--columns", "u=1,y=7", "--fs", "30000",
                                     *IDQ], g, setup=csv_variant("r.csv", header=None),
        hints=("--columns", "7", "r.csv"))
    cli("csv_columns_negative", [*ID, "r.csv", "--columns=u=-1,y=2", "--fs", "30000", *IDQ],
        g, setup=csv_variant("r.csv", header=None), hints=("--columns", "-1"))
    cli("csv_columns_unknown_name", [*ID, "r.csv", "--columns", "u=volt", *IDQ], g,
        setup=csv_variant("r.csv"), hints=("volt",))
    cli("csv_columns_u_is_t", [*ID, "r.csv", "--columns", "t=t,u=t,y=y", *IDQ], g,
        setup=csv_variant("r.csv"), hints=("--columns", "t"))
    idc("unicode_filename", "Mesung Ωµ é.csv", csv_variant("Mesung Ωµ é.csv"), expect="ok",
        judge=judge_fit())
    cli("dash_filename", [*ID, "--", "-r.csv", *IDQ], g, setup=csv_variant("-r.csv"),
        expect="ok", judge=judge_fit())
    idc("colon_filename_h5", "run 12:30.h5", h5_file(
        "run 12:30.h5", lambda fh: [fh.create_dataset("u", data=BASE.u),
                                    fh.create_dataset("y", data=BASE.y),
                                    fh.attrs.__setitem__("fs", FS)]), expect="any",
        judge=judge_fit())
    idc("upper_extension", "R.CSV", csv_variant("R.CSV"), expect="any", judge=judge_fit())
    idc("unknown_extension", "r.dat", csv_variant("r.dat"))
    idc("no_extension", "r", csv_variant("r"))
    idc("record_is_directory", "d.csv", lambda ws: (ws / "d.csv").mkdir(), quick=True)
    idc("record_is_fifo", "p.csv", fifo("p.csv"), quick=True)
    idc("record_dev_zero_csv", "z.csv", symlink("z.csv", "/dev/zero"), quick=True)
    idc("record_dev_zero_npz", "z.npz", symlink("z.npz", "/dev/zero"))
    idc("record_dev_urandom_h5", "z.h5", symlink("z.h5", "/dev/urandom"))
    idc("record_dangling_link", "l.csv", symlink("l.csv", "nowhere/none.csv"))
    idc("record_missing", "none.csv", None)

    # --- npz
    def npz(name: str, make: Callable[[], dict], **kw: Any) -> None:
        idc(name, "r.npz", npz_file("r.npz", make), **kw)

    npz("npz_plain", plain_arrays, expect="ok", judge=judge_fit(), quick=True)
    npz("npz_t_vector", lambda: {"t": BASE.t, "u": BASE.u, "y": BASE.y}, expect="ok",
        judge=judge_fit())
    npz("npz_missing_y", lambda: {"u": BASE.u, "fs": FS})
    npz("npz_u_2d", lambda: {**plain_arrays(), "u": np.vstack([BASE.u, BASE.u])}, quick=True)
    npz("npz_u_column", lambda: {**plain_arrays(), "u": BASE.u[:, None]}, expect="any",
        judge=judge_fit())
    npz("npz_object_array", lambda: {**plain_arrays(), "u": np.array(list(BASE.u),
                                                                        dtype=object)},
        quick=True)
    npz("npz_strings", lambda: {**plain_arrays(), "u": BASE.u.astype(str)})
    npz("npz_complex", lambda: {**plain_arrays(), "u": BASE.u + 1j})
    npz("npz_bool", lambda: {**plain_arrays(), "u": BASE.u > 3})
    npz("npz_uint64_huge", lambda: {**plain_arrays(),
                                    "u": (BASE.u * 1e18).astype(np.uint64)}, expect="any",
        judge=judge_fit(), what="u as uint64 counts up to 6.8e18")
    npz("npz_big_endian", lambda: {**plain_arrays(), "u": BASE.u.astype(">f8")}, expect="ok",
        judge=judge_fit())
    npz("npz_float16", lambda: {**plain_arrays(), "y": BASE.y.astype(np.float16)},
        expect="any", judge=judge_fit(tol=1e9))
    npz("npz_length_mismatch", lambda: {**plain_arrays(), "y": BASE.y[:-7]})
    npz("npz_empty_arrays", lambda: {"u": np.zeros(0), "y": np.zeros(0), "fs": FS})
    npz("npz_fs_zero", lambda: {**plain_arrays(), "fs": 0.0})
    npz("npz_fs_nan", lambda: {**plain_arrays(), "fs": np.nan})
    npz("npz_fs_vector", lambda: {**plain_arrays(), "fs": np.array([FS, 1.0])})
    npz("npz_fs_string", lambda: {**plain_arrays(), "fs": np.array("30 kHz")})
    npz("npz_nan_u", lambda: {**plain_arrays(), "u": np.where(np.arange(6000) == 9, np.nan,
                                                              BASE.u)})
    npz("npz_units_odd", lambda: {**plain_arrays(), "units": np.array([1, 2])}, expect="any",
        judge=judge_fit())
    idc("npz_truncated", "r.npz", truncated("r.npz", npz_file("r.npz", plain_arrays), 0.5),
        quick=True)
    idc("npz_not_zip", "r.npz", text_file("r.npz", "u,y\n1,2\n"))

    def npz_flag(flag: int, method: int | None = None) -> Callable[[Path], None]:
        def setup(ws: Path) -> None:
            npz_file("r.npz", plain_arrays)(ws)
            data = bytearray((ws / "r.npz").read_bytes())
            pos = 0
            while True:  # every local header and central directory entry
                pos = data.find(b"PK\x03\x04", pos)
                if pos < 0:
                    break
                data[pos + 6:pos + 8] = struct.pack("<H", flag)
                if method is not None:
                    data[pos + 8:pos + 10] = struct.pack("<H", method)
                pos += 4
            pos = 0
            while True:
                pos = data.find(b"PK\x01\x02", pos)
                if pos < 0:
                    break
                data[pos + 8:pos + 10] = struct.pack("<H", flag)
                if method is not None:
                    data[pos + 10:pos + 12] = struct.pack("<H", method)
                pos += 4
            (ws / "r.npz").write_bytes(bytes(data))
        return setup
    idc("npz_method_lzma_claimed", "r.npz", npz_flag(0, 14))

    def npz_huge_header(ws: Path) -> None:
        header = {"descr": "<f8", "fortran_order": False, "shape": (10**11,)}
        with zipfile.ZipFile(ws / "r.npz", "w") as zf:
            for key in ("u", "y"):
                buf = _npy_header(header) + np.zeros(100).tobytes()
                zf.writestr(f"{key}.npy", buf)
            zf.writestr("fs.npy", _npy_bytes(np.float64(FS)))
    idc("npz_declared_1e11_samples", "r.npz", npz_huge_header, quick=True)

    def npz_bomb(ws: Path) -> None:
        n = 20_000_000
        with zipfile.ZipFile(ws / "r.npz", "w", compression=zipfile.ZIP_DEFLATED) as zf:
            for key in ("u", "y"):
                with zf.open(f"{key}.npy", "w", force_zip64=True) as fh:
                    fh.write(_npy_header({"descr": "<f8", "fortran_order": False,
                                          "shape": (n,)}))
                    block = np.zeros(1_000_000).tobytes()
                    for _ in range(n // 1_000_000):
                        fh.write(block)
            zf.writestr("fs.npy", _npy_bytes(np.float64(FS)))
    def long_npz(n: int) -> Callable[[Path], None]:
        def make() -> dict[str, Any]:
            reps = -(-n // len(BASE.u))
            return {"u": np.tile(BASE.u, reps)[:n], "y": np.tile(BASE.y, reps)[:n], "fs": FS}
        return npz_file("r.npz", make)
    idc("long_record_batch_1.2M", "r.npz", long_npz(1_200_000), ["--holdout", "0"], quick=True,
        what="1.2e6 samples for a batch fit: refused before any work")
    cli("long_record_online_3.1M", [*ID, "r.npz", "--method", "online", "--holdout", "0",
                                    *IDQ], g,
        setup=long_npz(3_100_000), hints=("r.npz", "samples"),
        what="3.1e6 samples for an on-line fit: refused before any work")
    idc("npz_compressed_20M_zeros", "r.npz", npz_bomb,
        what="2 x 160 MB of zeros deflated to well under 1 MB")

    # --- mat
    def mat(name: str, make: Callable[[], dict], **kw: Any) -> None:
        idc(name, "r.mat", mat_file("r.mat", make), **kw)

    mat("mat_plain", plain_arrays, expect="ok", judge=judge_fit(), quick=True)
    mat("mat_row_vectors", lambda: {"u": BASE.u[None, :], "y": BASE.y[None, :], "fs": FS},
        expect="ok", judge=judge_fit())
    mat("mat_matrix_u", lambda: {**plain_arrays(), "u": np.vstack([BASE.u, BASE.u])})
    mat("mat_struct", lambda: {"data": {"u": BASE.u, "y": BASE.y, "fs": FS}})
    mat("mat_char_u", lambda: {**plain_arrays(), "u": "not a signal"})
    mat("mat_cell_u", lambda: {**plain_arrays(), "u": np.array([BASE.u, BASE.y],
                                                               dtype=object)})
    mat("mat_empty_u", lambda: {**plain_arrays(), "u": np.zeros((0, 0))})
    idc("mat_truncated", "r.mat", truncated("r.mat", mat_file("r.mat", plain_arrays), 0.6),
        quick=True)
    idc("mat_garbage", "r.mat", text_file("r.mat", b"MATLAB 5.0 MAT-file" + b"\xff" * 300))

    def mat73(ws: Path) -> None:
        import h5py
        with h5py.File(ws / "r.mat", "w", userblock_size=512) as fh:
            fh.create_dataset("u", data=BASE.u[:, None])
            fh.create_dataset("y", data=BASE.y[:, None])
            fh.create_dataset("fs", data=np.array([[FS]]))
        with open(ws / "r.mat", "r+b") as fh:
            fh.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 "
                     b"00:00:00 2024 HDF5 schema 1.00 .".ljust(116) + b"\0" * 8
                     + b"\x00\x02IM")
    idc("mat_v73_hdf5", "r.mat", mat73, expect="any", judge=judge_fit())

    # --- hdf5
    def h5(name: str, fill: Callable[[Any], None], arg: str = "r.h5", **kw: Any) -> None:
        idc(name, arg, h5_file("r.h5", fill), **kw)

    def fill_plain(fh: Any) -> None:
        fh.create_dataset("u", data=BASE.u)
        fh.create_dataset("y", data=BASE.y)
        fh.attrs["fs"] = FS
    h5("h5_plain", fill_plain, expect="ok", judge=judge_fit(), quick=True)

    def fill_group(fh: Any) -> None:
        grp = fh.create_group("runs/a")
        grp.create_dataset("u", data=BASE.u)
        grp.create_dataset("y", data=BASE.y)
        grp.attrs["fs"] = FS
    h5("h5_group", fill_group, "r.h5:runs/a", expect="ok", judge=judge_fit(),
       hints=("r.h5",))
    h5("h5_missing_group", fill_group, "r.h5:runs/zz", hints=("zz",))
    h5("h5_group_is_dataset", fill_group, "r.h5:runs/a/u", hints=("runs/a/u", "r.h5"))

    def fill_lazy(fh: Any) -> None:
        fh.create_dataset("u", shape=(10**10,), dtype="f8", chunks=(10**5,))
        fh.create_dataset("y", shape=(10**10,), dtype="f8", chunks=(10**5,))
        fh.attrs["fs"] = FS
    h5("h5_declared_1e10_samples", fill_lazy, quick=True)

    def fill_strings(fh: Any) -> None:
        fh.create_dataset("u", data=np.array([b"a", b"b"] * 3000))
        fh.create_dataset("y", data=BASE.y)
        fh.attrs["fs"] = FS
    h5("h5_string_u", fill_strings)

    def fill_2d(fh: Any) -> None:
        fh.create_dataset("u", data=np.vstack([BASE.u, BASE.u]))
        fh.create_dataset("y", data=BASE.y)
        fh.attrs["fs"] = FS
    h5("h5_2d_u", fill_2d)

    def fill_external(fh: Any) -> None:
        import h5py
        fh["u"] = h5py.ExternalLink("gone.h5", "/u")
        fh.create_dataset("y", data=BASE.y)
        fh.attrs["fs"] = FS
    h5("h5_external_link_missing", fill_external)

    def fill_soft_loop(fh: Any) -> None:
        import h5py
        fh["u"] = h5py.SoftLink("/u")
        fh.create_dataset("y", data=BASE.y)
        fh.attrs["fs"] = FS
    h5("h5_soft_link_loop", fill_soft_loop)

    def fill_fs_string(fh: Any) -> None:
        fh.create_dataset("u", data=BASE.u)
        fh.create_dataset("y", data=BASE.y)
        fh.attrs["fs"] = "thirty kilohertz"
    h5("h5_fs_string", fill_fs_string)

    def fill_u_group(fh: Any) -> None:
        fh.create_group("u")
        fh.create_dataset("y", data=BASE.y)
        fh.attrs["fs"] = FS
    h5("h5_u_is_group", fill_u_group)

    def fill_scalar(fh: Any) -> None:
        fh.create_dataset("u", data=1.0)
        fh.create_dataset("y", data=BASE.y)
        fh.attrs["fs"] = FS
    h5("h5_scalar_u", fill_scalar)
    idc("h5_truncated", "r.h5", truncated("r.h5", h5_file("r.h5", fill_plain), 0.5),
        quick=True)

    def fill_filter(fh: Any) -> None:
        fh.create_dataset("u", data=BASE.u, compression="lzf")
        fh.create_dataset("y", data=BASE.y, compression="gzip", shuffle=True)
        fh.attrs["fs"] = FS
    h5("h5_compressed", fill_filter, expect="ok", judge=judge_fit())


def _npy_header(header: dict) -> bytes:
    """A .npy version 1.0 header for ``header``."""
    text = repr(header).encode("latin1")
    pad = 64 - (10 + len(text) + 1) % 64
    text += b" " * pad + b"\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(text)) + text


def _npy_bytes(arr: np.ndarray) -> bytes:
    """The .npy bytes of ``arr``."""
    import io
    buf = io.BytesIO()
    np.save(buf, arr)
    return buf.getvalue()


def add_identify_option_cases() -> None:
    """Odd options of ``hystid identify`` on the base record."""
    g = "identify_options"
    base = copy_base("train.csv", "val.csv")

    def opt(name: str, extra: list[str], hints: tuple[str, ...], **kw: Any) -> None:
        tail = IDQ if "--out" not in extra else ["--json", "--quiet"]
        cli(name, [*ID, "train.csv", *extra, *tail], g, setup=kw.pop("setup", base),
            hints=hints, **kw)

    for v in ("0", "-1", "nan", "inf", "1e308"):
        opt(f"fs_{v}", [f"--fs={v}"], ("--fs", "fs="), quick=v in ("0", "nan"))
    opt("fs_conflicts_with_t", ["--fs", "1000"], ("--fs", "1000"))
    for v in ("5:1", "0:1e308", "nan:1", "0:0", "-1:0.1", "0.199:0.2", "abc", "0:inf"):
        opt(f"crop_{v}", [f"--crop={v}"], ("--crop", "train.csv"),
            quick=v in ("0:1e308", "nan:1"),
            expect="error" if v not in ("0:1e308", "0:inf", "-1:0.1") else "any",
            judge=None if v not in ("0:1e308", "0:inf", "-1:0.1") else judge_fit())
    for v in ("1", "-0.1", "nan", "0.9999", "1e-9"):
        opt(f"holdout_{v}", ["--holdout", v], ("--holdout",), quick=v == "nan")
    for v in ("-1", "1e9", "nan", "inf"):
        opt(f"skip_{v}", [f"--skip={v}"], ("--skip",), quick=v == "1e9")
    for v in ("q1=1000000000", "n1a=-1", "n2a=40", "garbage", "q1=1.5", "f0=maybe",
              "n1a=1,n1a=2", "q2=5000"):
        opt(f"structure_{v}", ["--structure", v], ("--structure",), quick=v == "q1=1000000000")
    opt("units_empty", ["--units", "u=,y="], ("--units",))
    opt("units_extra_role", ["--units", "u=V,y=um,t=s"], ("--units",))
    opt("units_control_chars", ["--units", "u=V\x1b[31m,y=um\nmore"], ("--units",),
        expect="any", judge=judge_fit())
    opt("method_eria_model_pi", ["--method", "eria", "--model", "pi"], ("--method", "--model"))
    opt("method_online_model_mduhem", ["--method", "online", "--model", "mduhem"],
        ("--method", "--model", "mduhem"))
    opt("offset_none_with_offset", ["--offset", "none"], ("--offset",), expect="ok")
    opt("history_batch", ["--history", "h.csv"], ("--history",))
    opt("history_is_record", ["--method", "online", "--history", "train.csv", "--force"],
        ("--history", "train.csv"), quick=True)
    opt("history_is_val", ["--method", "online", "--val", "val.csv", "--history", "val.csv",
                           "--force"], ("--history", "val.csv"))
    opt("history_fifo_forced", ["--method", "online", "--history", "h.csv", "--force"],
        ("--history", "h.csv"), setup=both(base, fifo("h.csv")), expect="any",
        what="--history a named pipe, with --force")
    opt("history_is_out_file", ["--method", "online", "--history", "rep/report.json"],
        ("--history",))
    opt("history_exists", ["--method", "online", "--history", "h.csv"], ("--history", "h.csv"),
        setup=both(base, text_file("h.csv", "user's notes\n")))
    cli("out_is_record", [*ID, "train.csv", "--json", "--quiet", "--out", "train.csv"], g,
        setup=base, hints=("--out", "train.csv"), quick=True)
    cli("out_is_record_forced", [*ID, "train.csv", "--json", "--quiet", "--out", "train.csv",
                                 "--force"], g, setup=base, hints=("--out", "train.csv"))
    cli("out_is_record_folder", [*ID, "data/train.csv", "--json", "--quiet", "--out", "data"],
        g, setup=lambda ws: (ws / "data").mkdir() or base(ws / "data"), hints=("--out",),
        expect="any", what="new files written beside the records: sound while none is lost")
    cli("out_is_record_folder_forced", [*ID, "data/train.csv", "--json", "--quiet", "--out",
                                        "data", "--force"], g,
        setup=lambda ws: (ws / "data").mkdir() or base(ws / "data"), hints=("--out",),
        quick=True, what="--force on the folder that holds the record: the record must stay",
        expect="any")
    cli("out_is_val_folder_forced", [*ID, "train.csv", "--val", "v/val.csv", "--json",
                                     "--quiet", "--out", "v", "--force"], g,
        setup=lambda ws: (base(ws), (ws / "v").mkdir(), shutil.copy(ws / "val.csv",
                                                                    ws / "v/val.csv")),
        hints=("--out",), expect="any")
    cli("out_exists_user_file", [*ID, "train.csv", "--json", "--quiet", "--out", "mine"], g,
        setup=lambda ws: (base(ws), (ws / "mine").mkdir(),
                          (ws / "mine/model.json").write_text("my own model\n")),
        hints=("--out", "mine"))
    cli("out_forced_user_file", [*ID, "train.csv", "--json", "--quiet", "--out", "mine",
                                 "--force"], g,
        setup=lambda ws: (base(ws), (ws / "mine").mkdir(),
                          (ws / "mine/model.json").write_text("my own model\n")),
        replaceable=("mine/model.json",), expect="ok")
    opt("out_in_proc", ["--out", "/proc/hystid-audit"], ("/proc", "--out"))
    opt("out_under_file", ["--out", "train.csv/sub"], ("train.csv", "--out"))
    opt("val_is_record", ["--val", "train.csv"], ("--val",), expect="any",
        judge=judge_fit(need_warning=True),
        what="--val the record itself: its figures are not held out, and must say so")
    opt("val_other_rate", ["--val", "v10k.csv"], ("--val", "v10k.csv", "rate", "fs"),
        setup=both(base, csv_arrays("v10k.csv", lambda: (np.arange(2000) / 1e4,
                                                         BASE.uv[::3], BASE.yv[::3]))))
    opt("val_other_units", ["--val", "vnm.npz"], ("--val", "vnm.npz", "unit"),
        setup=both(base, npz_file("vnm.npz", lambda: {
            "u": BASE.uv, "y": BASE.yv * 1e3, "fs": FS,
            "units": np.array(json.dumps({"u": "V", "y": "nm"}))})),
        expect="any", judge=judge_fit(), quick=True,
        what="a --val record stored in nm for a record in um")
    opt("val_units_unreadable", ["--val", "vnm.npz"], ("--val", "vnm.npz", "unit"),
        setup=both(base, npz_file("vnm.npz", lambda: {"u": BASE.uv, "y": BASE.yv * 1e3,
                                                      "fs": FS, "units": np.array("u=V,y=nm")})),
        expect="any", judge=judge_fit(),
        what="a record whose stored units ('u=V,y=nm') are not in hystid's form")
    opt("repeat_other_units", ["--val", "val.csv", "--repeat", "rnm.npz"], ("rnm.npz", "unit"),
        setup=both(base, npz_file("rnm.npz", lambda: {
            "u": BASE.uv, "y": BASE.yv * 1e3, "fs": FS,
            "units": np.array(json.dumps({"u": "V", "y": "nm"}))})),
        expect="any", judge=judge_floor_units)
    opt("val_fifo", ["--val", "p.csv"], ("p.csv",), setup=both(base, fifo("p.csv")))
    opt("val_two_samples", ["--val", "v2.csv"], ("v2.csv",),
        setup=both(base, text_file("v2.csv", "t,u,y\n0,1,1\n3.3333333333333335e-05,2,2\n")))
    opt("repeat_other_length", ["--val", "val.csv", "--repeat", "rp.csv"], ("rp.csv",),
        setup=both(base, csv_arrays("rp.csv", lambda: (BASE.t[:3000], BASE.uv[:3000],
                                                       BASE.yv[:3000]))))
    opt("repeat_other_input", ["--val", "val.csv", "--repeat", "rp.csv"], ("rp.csv",),
        setup=both(base, csv_arrays("rp.csv", lambda: (BASE.t, BASE.u, BASE.y))),
        expect="any", what="a --repeat record whose input is not the validation input")


def add_semantic_cases() -> None:
    """Semantically wrong or transformed data, through ``hystid identify``."""
    g = "semantics"
    rng = np.random.default_rng(11)
    noise = rng.normal(0.0, 1.0, 6000)
    drift = np.linspace(0, 3.0, 6000) + np.random.default_rng(12).normal(0, 1e-3, 6000)

    def pair(name: str, mu: Callable, my: Callable, extra: list[str] | None = None,
             judge: Callable | None = None, **kw: Any) -> None:
        def setup(ws: Path) -> None:
            write_csv(ws / "tr.csv", BASE.t, mu(BASE.u, "train"), my(BASE.y, BASE.u, "train"))
            write_csv(ws / "va.csv", BASE.t, mu(BASE.uv, "val"), my(BASE.yv, BASE.uv, "val"),
                      fmt="%.17g")
        cli(name, [*ID, "tr.csv", "--val", "va.csv", *(extra or []), *IDQ], g, setup=setup,
            judge=judge, expect="any", **kw)

    ident_u = lambda u, which: u  # noqa: E731
    ident_y = lambda y, u, which: y  # noqa: E731
    for off in (1e2, 1e4, 1e6):
        pair(f"input_offset_{off:g}", lambda u, w, o=off: u + o, ident_y,
             judge=judge_same(lambda u, o=off: u + o, lambda y: y, f"input + {off:g}"),
             quick=off == 1e6)
    pair("output_offset_1e6", ident_u, lambda y, u, w: y + 1e6,
         judge=judge_same(lambda u: u, lambda y: y - 1e6, "output + 1e6"))
    pair("input_in_nV", lambda u, w: u * 1e9, ident_y, extra=["--units", "u=nV,y=um"],
         judge=judge_same(lambda u: u * 1e9, lambda y: y, "u in nV"), quick=True)
    pair("output_in_km", ident_u, lambda y, u, w: y * 1e-9, extra=["--units", "u=V,y=km"],
         judge=judge_same(lambda u: u, lambda y: y * 1e9, "y in km"))
    pair("output_1e300", ident_u, lambda y, u, w: y * 1e300,
         judge=judge_same(lambda u: u, lambda y: y * 1e-300, "y x 1e300"))
    pair("input_1e-300", lambda u, w: u * 1e-300, ident_y,
         judge=judge_same(lambda u: u * 1e-300, lambda y: y, "u x 1e-300"))
    pair("output_1e-300", ident_u, lambda y, u, w: y * 1e-300,
         judge=judge_same(lambda u: u, lambda y: y * 1e300, "y x 1e-300"))
    pair("input_1e80", lambda u, w: u * 1e80, ident_y,
         judge=judge_same(lambda u: u * 1e80, lambda y: y, "u x 1e80"))
    pair("output_negated", ident_u, lambda y, u, w: -y,
         judge=judge_same(lambda u: u, lambda y: -y, "y negated"))
    pair("online_input_offset_1e6", lambda u, w: u + 1e6, ident_y,
         extra=["--method", "online"],
         judge=judge_same(lambda u: u + 1e6, lambda y: y, "on-line, input + 1e6", rel=3.0))

    def cut(ws: Path) -> None:
        write_csv(ws / "tr.csv", BASE.t[:4500], BASE.u[1500:], BASE.y[1500:])
        write_csv(ws / "va.csv", BASE.t, BASE.uv, BASE.yv)
    cli("not_at_rest", [*ID, "tr.csv", "--val", "va.csv", *IDQ], g, setup=cut,
        judge=judge_fit(), expect="any", what="train starts mid-motion")

    def glitch(u: np.ndarray, which: str) -> np.ndarray:
        u = u.copy()
        if which == "train":
            u[3000] = 100.0
        return u
    pair("input_glitch_100V", glitch, ident_y,
         judge=judge_same(lambda u: u, lambda y: y, "one input sample at 100 V"))

    def outlier(y: np.ndarray, u: np.ndarray, which: str) -> np.ndarray:
        y = y.copy()
        if which == "train":
            y[2500] = 1e12
        return y
    pair("output_outlier_1e12", ident_u, outlier,
         judge=judge_same(lambda u: u, lambda y: y, "one output sample at 1e12"))

    def burst(y: np.ndarray, u: np.ndarray, which: str) -> np.ndarray:
        y = y.copy()
        if which == "train":
            y[2000:2100] += 5.0
        return y
    pair("output_burst", ident_u, burst,
         judge=judge_same(lambda u: u, lambda y: y, "a 100-sample +5 um burst", rel=1.0))

    def clipped(y: np.ndarray, u: np.ndarray, which: str) -> np.ndarray:
        return np.minimum(y, 4.0)
    pair("output_saturated_sensor", ident_u, clipped,
         judge=judge_suspect("a sensor clipped at 4 um on train and val"))
    pair("output_pure_noise", ident_u, lambda y, u, w: noise.copy() if w == "train"
         else np.random.default_rng(13).normal(0, 1, 6000),
         judge=judge_suspect("an output of pure noise"), quick=True)
    pair("output_drift_only", ident_u, lambda y, u, w: drift.copy(),
         judge=judge_suspect("an output that is only drift"))
    pair("output_constant", ident_u, lambda y, u, w: np.full(6000, 2.0))
    pair("output_is_input", ident_u, lambda y, u, w: u.copy())
    pair("output_scaled_input", ident_u, lambda y, u, w: 0.9 * u + 0.1,
         judge=judge_suspect("an output that is a static line of the input"))
    pair("input_constant", lambda u, w: np.full(6000, 5.0), ident_y, quick=True)
    pair("input_single_step", lambda u, w: np.where(np.arange(6000) < 300, 0.0, 5.0),
         ident_y)

    def swapped(ws: Path) -> None:
        write_csv(ws / "tr.csv", BASE.t, BASE.u, BASE.y)
        write_csv(ws / "va.csv", BASE.t, BASE.uv, BASE.yv)
    cli("swapped_columns", [*ID, "tr.csv", "--val", "va.csv", "--columns", "u=y,y=u", *IDQ],
        g, setup=swapped, expect="any", quick=True,
        judge=judge_suspect("u and y swapped (the output drives the model)"))

    def lead(y: np.ndarray, u: np.ndarray, which: str) -> np.ndarray:
        return np.r_[y[40:], np.full(40, y[-1])]
    pair("output_leads_input", ident_u, lead,
         judge=judge_suspect("the output leads the input by 40 samples"))

    def other_stage(y: np.ndarray, u: np.ndarray, which: str) -> np.ndarray:
        return y if which == "train" else 2.5 * y
    pair("val_of_another_stage", ident_u, other_stage,
         judge=judge_suspect("a validation record of another stage (2.5x the gain)"))

    def quantised(y: np.ndarray, u: np.ndarray, which: str) -> np.ndarray:
        return np.round(y)
    pair("output_quantised_1um", ident_u, quantised, judge=judge_fit(tol=400))

    def huge_noise(y: np.ndarray, u: np.ndarray, which: str) -> np.ndarray:
        return y + np.random.default_rng(14 if which == "train" else 15).normal(0, 20, y.size)
    pair("output_noise_20um", ident_u, huge_noise,
         judge=judge_suspect("sensor noise 3x the output span"))


def add_simulate_cases() -> None:
    """``hystid simulate``: the built-in stage and a model on a record's input."""
    g = "simulate"
    sim = ["simulate"]
    s05 = ["simulate", "--seconds", "0.05", "--seed", "0"]  # the built-in stage, 1500 samples
    for v in ("0", "-1", "nan", "inf", "1e-9", "601", "1e-4"):
        cli(f"sim_seconds_{v}", [*sim, f"--seconds={v}", "--seed", "0", "--out", "s.csv"], g,
            hints=("--seconds",), quick=v in ("1e-9", "nan"),
            expect="any" if v == "1e-4" else "error",
            judge=judge_file_ok("s.csv") if v == "1e-4" else None)
    for v in ("-1", str(2**70), "1.5", "abc"):
        cli(f"sim_seed_{v[:8]}", [*sim, "--seconds", "0.05", f"--seed={v}", "--out", "s.csv"],
            g, hints=("--seed",), quick=v == "-1")
    for v in ("-1", "nan", "inf", "1e300"):
        cli(f"sim_noise_{v}", [*s05, f"--noise={v}", "--out", "s.csv"],
            g, hints=("--noise",), quick=v == "nan",
            expect="any" if v == "1e300" else "error",
            judge=judge_file_ok("s.csv") if v == "1e300" else None)
    base = copy_base("train.csv", "model.json")
    cli("sim_model_plain", [*sim, "--model", "model.json", "--input", "train.csv", "--out",
                            "s.csv"], g, setup=base, expect="ok", judge=judge_file_ok("s.csv"),
        quick=True)
    cli("sim_model_without_input", [*sim, "--model", "model.json", "--out", "s.csv"], g,
        setup=base, hints=("--input",))
    cli("sim_input_without_model", [*sim, "--input", "train.csv", "--out", "s.csv"], g,
        setup=base, hints=("--model",))
    cli("sim_out_is_input", [*sim, "--model", "model.json", "--input", "train.csv", "--out",
                             "train.csv"], g, setup=base, hints=("--out", "train.csv"),
        quick=True)
    cli("sim_out_is_input_forced", [*sim, "--model", "model.json", "--input", "train.csv",
                                    "--out", "train.csv", "--force"], g, setup=base,
        hints=("--out", "train.csv"), what="--force onto the record being read")
    cli("sim_out_is_model_forced", [*sim, "--model", "model.json", "--input", "train.csv",
                                    "--out", "model.json", "--force"], g, setup=base,
        hints=("--out", "model.json"))
    cli("sim_out_exists", [*s05, "--out", "s.csv"], g,
        setup=text_file("s.csv", "my data\n"), hints=("--out", "s.csv"), quick=True)
    cli("sim_out_unknown_ext", [*s05, "--out", "s.xyz"], g,
        hints=("s.xyz", ".xyz"))
    cli("sim_out_directory", [*s05, "--out", "d"], g,
        setup=lambda ws: (ws / "d").mkdir(), hints=("d", "--out"))
    cli("sim_out_proc", [*s05, "--out", "/proc/hystid_audit.csv"], g,
        hints=("/proc", "--out"))
    cli("sim_out_fifo_forced", [*s05, "--out", "p.csv", "--force"], g, setup=fifo("p.csv"),
        hints=("p.csv", "--out"), expect="any", judge=judge_file_ok("p.csv"),
        what="--force onto a named pipe: replaced by the file, or refused, never blocking")
    cli("sim_out_link_to_input", [*sim, "--model", "model.json", "--input", "train.csv",
                                  "--out", "l.csv", "--force"], g,
        setup=both(base, symlink("l.csv", "train.csv")), hints=("l.csv", "train.csv", "--out"),
        what="--out a link to the record being read")
    cli("sim_out_dangling_link", [*s05, "--out", "l.csv"], g,
        setup=symlink("l.csv", "/tmp/hystid-audit-nowhere/x.csv"), hints=("l.csv", "--out"))
    for ext in ("npz", "mat", "h5"):
        cli(f"sim_out_{ext}", [*s05, "--out", f"s.{ext}"], g,
            expect="ok", judge=judge_file_ok(f"s.{ext}"))
    cli("sim_out_unicode", [*s05, "--out", "Ω µ.csv"], g, expect="ok",
        judge=judge_file_ok("Ω µ.csv"))
    cli("sim_input_two_samples", [*sim, "--model", "model.json", "--input", "r.csv", "--out",
                                  "s.csv"], g, setup=both(base, text_file(
                                      "r.csv", "t,u,y\n0,0,0\n3.3333333333333335e-05,1,0\n")),
        expect="any", judge=judge_file_ok("s.csv"))
    cli("sim_input_name_control", [*sim, "--model", "model.json", "--input", "r.npz", "--out",
                                   "s.csv"], g,
        setup=both(base, npz_file("r.npz", lambda: {**plain_arrays(),
                                                    "name": np.array("run 1\n# t,u,y\x1b[2J")})),
        expect="any", judge=judge_file_ok("s.csv"),
        what="a record named with a line break and an escape sequence")
    cli("sim_input_units_control", [*sim, "--model", "model.json", "--input", "r.npz", "--out",
                                    "s.csv"], g,
        setup=both(base, npz_file("r.npz", lambda: {
            **plain_arrays(), "units": np.array(json.dumps({"u": "V", "y": "um\nt,u,y"}))})),
        expect="any", judge=judge_file_ok("s.csv"), hints=("r.npz", "unit"))
    cli("sim_fs_conflict", [*sim, "--model", "model.json", "--input", "train.csv", "--fs",
                            "1000", "--out", "s.csv"], g, setup=base, hints=("--fs", "fs="))
    cli("sim_input_other_rate", [*sim, "--model", "model.json", "--input", "r10k.csv", "--out",
                                 "s.csv"], g,
        setup=both(base, csv_arrays("r10k.csv", lambda: (np.arange(2000) / 1e4, BASE.u[::3],
                                                         BASE.y[::3]))),
        hints=("r10k.csv", "rate", "Hz"), quick=True,
        what="a 10 kHz input for a 30 kHz model")
    cli("sim_input_beyond_envelope", [*sim, "--model", "model.json", "--input", "big.csv",
                                      "--out", "s.csv"], g,
        setup=both(base, csv_arrays("big.csv", lambda: (BASE.t, BASE.u * 30, BASE.y))),
        expect="error", what="an input 30x the identified range")


def add_model_file_cases() -> None:
    """Hostile model files, through ``simulate --model`` and the other commands."""
    g = "model_file"

    def sim(name: str, setup: Callable, quick: bool = False, expect: str = "error",
            judge: Callable | None = None, what: str = "") -> None:
        cli(name, ["simulate", "--model", "m.json", "--input", "train.csv", "--out", "s.csv"],
            g, setup=setup, hints=("m.json",), quick=quick, expect=expect, judge=judge,
            what=what)

    sim("model_empty", model_doc(raw=lambda s: ""), quick=True)
    sim("model_not_json", model_doc(raw=lambda s: s[: len(s) // 2]))
    sim("model_bom", model_doc(raw=lambda s: "\ufeff" + s), expect="any",
        judge=judge_file_ok("s.csv"))
    sim("model_top_list", model_doc(lambda d: [d]))
    sim("model_top_string", model_doc(lambda d: "duhem"))
    sim("model_missing_params", model_doc(delp("params")), quick=True)
    sim("model_missing_format", model_doc(delp("format")))
    sim("model_wrong_format", model_doc(setp("format", "something-else")))
    sim("model_version_99", model_doc(setp("version", 99)))
    sim("model_version_string", model_doc(setp("version", "1")))
    sim("model_kind_bogus", model_doc(setp("kind", "bogus")))
    sim("model_kind_missing", model_doc(delp("kind")), expect="any",
        judge=judge_file_ok("s.csv"))
    sim("model_alpha_string", model_doc(setp("params.alpha", "0.8")), quick=True,
        expect="any", judge=judge_file_ok("s.csv"), what="alpha written as the text '0.8'")
    sim("model_alpha_word", model_doc(setp("params.alpha", "fast")))
    sim("model_alpha_null", model_doc(setp("params.alpha", None)))
    sim("model_alpha_bool", model_doc(setp("params.alpha", True)))
    sim("model_alpha_nan", model_doc(setp("params.alpha", float("nan"))), quick=True)
    sim("model_alpha_infinity", model_doc(setp("params.alpha", float("inf"))))
    sim("model_alpha_1e400", model_doc(raw=lambda s: s.replace(
        '"alpha": ' + json.dumps(json.loads(s)["params"]["alpha"]), '"alpha": 1e400')))
    sim("model_alpha_negative", model_doc(setp("params.alpha", -0.8)), quick=True)
    sim("model_alpha_zero", model_doc(setp("params.alpha", 0.0)))
    sim("model_alpha_bigint", model_doc(raw=lambda s: s.replace(
        '"alpha": ' + json.dumps(json.loads(s)["params"]["alpha"]), '"alpha": ' + "9" * 400)))
    sim("model_g0_1e200", model_doc(setp("params.g0", 1e200)))
    sim("model_fs_bigint", model_doc(raw=lambda s: re.sub(r'"fs": [0-9.e+-]+',
                                                          '"fs": ' + "3" * 400, s)))
    sim("model_envelope_bool", model_doc(setp("envelope.slew", True)))
    sim("model_envelope_bigint", model_doc(raw=lambda s: s.replace('"u_min": 0.0',
                                                                   '"u_min": -' + "9" * 400)))
    sim("mduhem_rates_bigint", model_doc(raw=lambda s: s.replace('"rates": [',
                                                                 '"rates": [' + "7" * 400 + ", "),
                                         source="mduhem.json"))
    sim("model_offset_1e308", model_doc(setp("offset", 1e308)))
    sim("model_u_rest_1e300", model_doc(setp("u_rest", 1e300)))
    sim("model_rest_memory_nan", model_doc(setp("rest_memory", float("nan"))))
    sim("model_fs_zero", model_doc(setp("fs", 0)))
    sim("model_fs_negative", model_doc(setp("fs", -30000)))
    sim("model_fs_string", model_doc(setp("fs", "30 kHz")))
    cli("model_fs_mismatch_input", ["simulate", "--model", "m.json", "--input", "train.csv",
                                    "--out", "s.csv"], g, setup=model_doc(setp("fs", 10000.0)),
        hints=("m.json", "--input"), quick=True,
        what="a 10 kHz model on a 30 kHz record")
    sim("model_q1_1e9", model_doc(setp("structure.q1", 10**9)), quick=True)
    sim("model_q1_negative", model_doc(setp("structure.q1", -1)))
    sim("model_q1_float", model_doc(setp("structure.q1", 1.5)))
    sim("model_n2a_missing_param", model_doc(setp("structure.n2a", 3)))
    sim("model_extra_param", model_doc(setp("params.a99", 0.5)))
    sim("model_extra_top_key", model_doc(setp("comment", "from the lab")), expect="any",
        judge=judge_file_ok("s.csv"))
    sim("model_params_list", model_doc(setp("params", [0.8, 0.1, 0.004, -0.5, -1.6, 0.9])))
    sim("model_param_array", model_doc(setp("params.a11", [0.0] * 1000)))
    sim("model_l2_pole_on_circle", model_doc(both_edit(setp("params.a21", -2.0),
                                                       setp("params.a22", 1.0))), quick=True)
    sim("model_l2_unstable_1p02", model_doc(both_edit(setp("params.a21", -2.04),
                                                      setp("params.a22", 1.0404))))
    sim("model_l1_unstable", model_doc(setp("params.a11", -1.5)))
    sim("model_envelope_inverted", model_doc(both_edit(setp("envelope.u_min", 10.0),
                                                       setp("envelope.u_max", 0.0))))
    sim("model_envelope_nan", model_doc(setp("envelope.slew", float("nan"))))
    sim("model_envelope_missing", model_doc(delp("envelope")), expect="any",
        judge=judge_file_ok("s.csv"))
    sim("model_units_list", model_doc(setp("units", ["V", "um"])))
    sim("model_units_number", model_doc(setp("units.y", 5)))
    sim("model_units_control", model_doc(setp("units.y", "um\x1b[2J\nFAKE LINE")),
        expect="any", judge=judge_file_ok("s.csv"))
    sim("model_name_huge", model_doc(setp("name", "n" * 2_000_000)), expect="any",
        judge=judge_file_ok("s.csv"))
    sim("model_provenance_string", model_doc(setp("provenance", "lab")), expect="any",
        judge=judge_file_ok("s.csv"))
    sim("model_provenance_deep", model_doc(raw=lambda s: s[:-1] + ', "x": ' + "[" * 100_000
                                           + "]" * 100_000 + "}"), quick=True,
        expect="any", judge=judge_file_ok("s.csv"))
    sim("model_provenance_deep_dict", model_doc(raw=lambda s: s[:-1] + ', "provenance2": '
                                                + '{"a":' * 5000 + "1" + "}" * 5000 + "}"),
        expect="any", judge=judge_file_ok("s.csv"))
    sim("model_huge_array_in_provenance", model_doc(setp("provenance.trace",
                                                         [0.125] * 1_500_000)), expect="any",
        judge=judge_file_ok("s.csv"), what="a 12 MB list in the provenance")
    sim("model_over_16MiB", model_doc(raw=lambda s: s + " " * (17 << 20)), quick=True)
    sim("model_duplicate_keys", model_doc(raw=lambda s: s.replace(
        '"params": {', '"params": {"alpha": -5, ', 1)), expect="any",
        judge=judge_file_ok("s.csv"), what="alpha given twice (-5, then the fitted one)")
    sim("model_is_directory", lambda ws: (copy_base("train.csv")(ws), (ws / "m.json").mkdir()))
    sim("model_is_fifo", lambda ws: (copy_base("train.csv")(ws), os.mkfifo(ws / "m.json")),
        quick=True)
    sim("model_dev_zero", lambda ws: (copy_base("train.csv")(ws),
                                      os.symlink("/dev/zero", ws / "m.json")), quick=True)
    sim("model_dev_urandom", lambda ws: (copy_base("train.csv")(ws),
                                         os.symlink("/dev/urandom", ws / "m.json")))
    sim("model_link_to_model", lambda ws: (copy_base("train.csv", "model.json")(ws),
                                           os.symlink("model.json", ws / "m.json")),
        expect="any", judge=judge_file_ok("s.csv"))
    sim("model_report_json", lambda ws: (copy_base("train.csv")(ws), shutil.copy(
        BASE.dir / "rep/report.json", ws / "m.json")), expect="any",
        judge=judge_file_ok("s.csv"), what="the report.json given where a model is expected")
    # PI and multi-Duhem files
    sim("pi_thresholds_1e300", model_doc(pi_edit("thresholds", 1e300), source="pi.json"),
        quick=True)
    sim("pi_mu_1e400", model_doc(raw=lambda s: s.replace('"mu0": ', '"mu0": 1e400, "x": ', 1),
                                 source="pi.json"))
    sim("pi_n_operators_mismatch", model_doc(setp("structure.n_operators", 21),
                                             source="pi-stage.json"))
    sim("pi_thresholds_unsorted", model_doc(pi_reverse("thresholds"), source="pi-stage.json"),
        expect="any", judge=judge_file_ok("s.csv"))
    sim("pi_thresholds_huge_list", model_doc(pi_resize("thresholds", 100_000),
                                             source="pi-stage.json"))
    sim("pi_poly_n_poly_more", model_doc(setp("structure.n_poly", 3), source="pi-poly.json"))
    sim("pi_poly_n_poly_negative", model_doc(setp("structure.n_poly", -1),
                                             source="pi-poly.json"))
    sim("pi_poly_c3_1e300", model_doc(setp("params.c3", 1e300), source="pi-poly.json"),
        expect="any", judge=judge_sim_output("s.csv"))
    sim("pi_poly_n_poly_dropped", model_doc(lambda d: d["structure"].pop("n_poly") and None,
                                            source="pi-poly.json"))
    sim("mduhem_rates_negative", model_doc(pi_edit("rates", -1.0), source="mduhem.json"))
    sim("mduhem_kind_as_duhem", model_doc(setp("kind", "duhem"), source="mduhem.json"))
    sim("duhem_kind_as_pi", model_doc(setp("kind", "pi")))
    sim("effects_bogus", model_doc(setp("effects", [{"name": "bogus", "params": {}}])))
    sim("effects_string", model_doc(setp("effects", "creep")))
    # the same files through other commands
    bad = model_doc(both_edit(setp("params.a21", -2.0), setp("params.a22", 1.0)))
    cli("compensate_model_pole_on_circle", ["compensate", "m.json", "--scan", "triangle:50:2",
                                            "--out", "c.csv"], g, setup=bad, hints=("m.json",))
    cli("export_model_pole_on_circle", ["export", "m.json", "--c", "cdir"], g, setup=bad,
        hints=("m.json",))
    cli("diagnose_model_pole_on_circle", ["diagnose", "train.csv", "--model", "m.json",
                                          "--quiet", "--time-budget", "0"], g, setup=bad,
        hints=("m.json",))
    cli("compensate_model_fifo", ["compensate", "m.json", "--scan", "triangle:50:2", "--out",
                                  "c.csv"], g, setup=fifo("m.json"), hints=("m.json",))
    cli("export_model_deep", ["export", "m.json", "--c", "cdir"], g,
        setup=model_doc(raw=lambda s: "[" * 200_000 + "]" * 200_000), hints=("m.json",))
    cli("export_pi_thresholds_1e300", ["export", "m.json", "--c", "cdir"], g,
        setup=model_doc(pi_edit("thresholds", 1e300), source="pi.json"), hints=("m.json",))
    cli("compensate_model_alpha_negative", ["compensate", "m.json", "--scan", "sine:50:2",
                                            "--out", "c.csv"], g,
        setup=model_doc(setp("params.alpha", -0.8)), hints=("m.json",))


def both_edit(*edits: Callable[[dict], Any]) -> Callable[[dict], None]:
    """Several edits of a model document."""
    def edit(doc: dict) -> None:
        for e in edits:
            e(doc)
    return edit


def _find_list(doc: Any, key: str) -> list | None:
    """The first list stored under ``key`` anywhere in ``doc``."""
    if isinstance(doc, dict):
        for k, v in doc.items():
            if k == key and isinstance(v, list):
                return v
            found = _find_list(v, key)
            if found is not None:
                return found
    return None


def _set_list(doc: Any, key: str, value: list) -> bool:
    """Replace the first list stored under ``key`` anywhere in ``doc``."""
    if isinstance(doc, dict):
        for k, v in doc.items():
            if k == key and isinstance(v, list):
                doc[k] = value
                return True
            if _set_list(v, key, value):
                return True
    return False


def pi_edit(key: str, value: float) -> Callable[[dict], None]:
    """An edit setting every entry of the list ``key`` (a PI or multi-Duhem model's) to
    ``value``; a document without it gets ``params[key]`` set instead."""
    def edit(doc: dict) -> None:
        old = _find_list(doc, key)
        if old is None:
            doc.setdefault("params", {})[key] = value
        else:
            _set_list(doc, key, [value] * len(old))
    return edit


def pi_reverse(key: str) -> Callable[[dict], None]:
    """An edit reversing the list ``key``."""
    def edit(doc: dict) -> None:
        old = _find_list(doc, key)
        if old is not None:
            _set_list(doc, key, old[::-1])
    return edit


def pi_resize(key: str, n: int) -> Callable[[dict], None]:
    """An edit making the list ``key`` ``n`` entries long."""
    def edit(doc: dict) -> None:
        old = _find_list(doc, key) or [0.1]
        _set_list(doc, key, (old * (n // len(old) + 1))[:n])
    return edit


def add_compensate_cases() -> None:
    """``hystid compensate``."""
    g = "compensate"
    base = copy_base("model.json", "train.csv")

    def comp(name: str, extra: list[str], hints: tuple[str, ...], **kw: Any) -> None:
        cli(name, ["compensate", "model.json", *extra, "--out", "c.csv"], g,
            setup=kw.pop("setup", base), hints=hints, **kw)

    comp("comp_scan_plain", ["--scan", "triangle:50:2"], (), expect="ok", quick=True)
    for v in ("triangle:0:2", "sine:-5:2", "triangle:1e9:2", "square:50:2", "triangle:50:nan",
              "triangle:50:1e300", "triangle:50", "garbage", "sine:50:0", "triangle:inf:2"):
        comp(f"comp_scan_{v}", [f"--scan={v}"], ("--scan",),
             quick=v in ("triangle:1e9:2", "triangle:50:nan"))
    for v in ("0", "-1", "1e9", "nan"):
        comp(f"comp_seconds_{v}", ["--scan", "triangle:50:2", f"--seconds={v}"],
             ("--seconds",), quick=v == "1e9")
    comp("comp_reference_record", ["--reference", "train.csv"], (), expect="ok",
         judge=None)
    comp("comp_scan_and_reference", ["--reference", "train.csv", "--scan", "sine:50:2"],
         ("--scan", "--reference"))
    for v in ("5:1", "nan:1", "0:0", "-inf:inf", "a:b"):
        comp(f"comp_limits_{v}", ["--scan", "triangle:50:2", f"--limits={v}"], ("--limits",),
             quick=v == "nan:1")
    for v in ("-1", "nan", "1e300"):
        comp(f"comp_margin_{v}", ["--scan", "triangle:50:2", f"--margin={v}"], ("--margin",))
    for v in ("2", "4", "-3", "1000000001"):
        comp(f"comp_smooth_{v}", ["--scan", "triangle:50:2", f"--smooth={v}"], ("--smooth",),
             quick=v == "1000000001")
    cli("comp_out_is_model_forced", ["compensate", "model.json", "--scan", "triangle:50:2",
                                     "--out", "model.json", "--force"], g, setup=base,
        hints=("--out", "model.json"), quick=True)
    cli("comp_out_exists", ["compensate", "model.json", "--scan", "triangle:50:2", "--out",
                            "c.csv"], g, setup=both(base, text_file("c.csv", "mine\n")),
        hints=("--out", "c.csv"))
    cli("comp_out_not_csv", ["compensate", "model.json", "--scan", "triangle:50:2", "--out",
                             "c.npz"], g, setup=base, hints=("--out", "c.npz"), expect="any")
    comp("comp_reference_fifo", ["--reference", "p.csv"], ("p.csv",),
         setup=both(base, fifo("p.csv")))
    comp("comp_reference_other_rate", ["--reference", "r10k.csv"], ("r10k.csv", "rate", "Hz"),
         setup=both(base, csv_arrays("r10k.csv", lambda: (np.arange(2000) / 1e4, BASE.u[::3],
                                                          BASE.y[::3]))))
    comp("comp_reference_in_nm", ["--reference", "rnm.npz"], ("rnm.npz", "unit", "nm"),
         setup=both(base, npz_file("rnm.npz", lambda: {
             "u": BASE.u, "y": BASE.y * 1e3, "fs": FS,
             "units": np.array(json.dumps({"u": "V", "y": "nm"}))})),
         expect="any", what="a reference in nm for a model in um")
    comp("comp_reference_nan", ["--reference", "rn.npz"], ("rn.npz",),
         setup=both(base, npz_file("rn.npz", lambda: {
             "u": BASE.u, "y": np.where(np.arange(6000) == 7, np.nan, BASE.y), "fs": FS})))
    comp("comp_reference_1e12", ["--reference", "rb.csv"], ("rb.csv",),
         setup=both(base, csv_arrays("rb.csv", lambda: (BASE.t, BASE.u, BASE.y * 1e12))),
         expect="any", what="a reference 1e12 x the model's range")


def add_diagnose_cases() -> None:
    """``hystid diagnose`` (each run is a few seconds: a smaller set)."""
    g = "diagnose"
    base = copy_base("train.csv", "val.csv")
    d = ["diagnose", "train.csv", "--quiet", "--time-budget", "0"]

    def diag(name: str, extra: list[str], hints: tuple[str, ...], **kw: Any) -> None:
        cli(name, [*d, *extra], g, setup=kw.pop("setup", base), hints=hints, **kw)

    diag("diag_plain", ["--val", "val.csv", "--json"], (), expect="ok", quick=True,
         judge=judge_diag_sane)
    diag("diag_plain_text", ["--val", "val.csv"], (), expect="ok", judge=judge_diag_sane)
    diag("diag_effects_bogus", ["--effects", "bogus"], ("--effects", "bogus"), quick=True)
    diag("diag_effects_empty", ["--effects", ""], ("--effects",))
    for v in ("0", "21", "-1"):
        diag(f"diag_max_rounds_{v}", [f"--max-rounds={v}"], ("--max-rounds",),
             expect="any" if v == "0" else "error")
    for v in ("0", "1.5", "nan"):
        diag(f"diag_alpha_{v}", [f"--alpha={v}"], ("--alpha",), quick=v == "nan")
    for v in ("1", "0", "nan"):
        diag(f"diag_holdout_{v}", [f"--holdout={v}"], ("--holdout",))
    for v in ("0", "nan", "-1"):
        diag(f"diag_u_scale_{v}", [f"--u-scale={v}"], ("--u-scale",), quick=v == "0")
    for v in ("-1", "nan"):
        diag(f"diag_time_budget_{v}", [f"--time-budget={v}"], ("--time-budget",))
    diag("diag_train_skip_1e9", ["--train-skip", "1e9"], ("--train-skip",))
    diag("diag_min_reduction_-1", ["--min-reduction=-1"], ("--min-reduction",))
    diag("diag_val_two_samples", ["--val", "v2.csv"], ("v2.csv",),
         setup=both(base, text_file("v2.csv", "t,u,y\n0,1,1\n3.3333333333333335e-05,2,2\n")))
    diag("diag_val_noise", ["--val", "vn.csv", "--json"], ("vn.csv",),
         setup=both(base, csv_arrays("vn.csv", lambda: (
             BASE.t, BASE.uv, np.random.default_rng(21).normal(0, 1, 6000)))),
         expect="any", judge=judge_diag_noise, what="a held-out record whose output is noise")
    cli("diag_out_record_folder_forced", ["diagnose", "data/train.csv", "--quiet",
                                          "--time-budget", "0", "--out", "data", "--force"], g,
        setup=lambda ws: (ws / "data").mkdir() or base(ws / "data"), hints=("--out",),
        expect="any")
    cli("diag_out_exists", [*d, "--out", "mine"], g,
        setup=lambda ws: (base(ws), (ws / "mine").mkdir(),
                          (ws / "mine/report.json").write_text("{}")),
        hints=("--out", "mine"))
    diag("diag_record_constant_input", [], ("train.csv",), setup=csv_arrays(
        "train.csv", lambda: (BASE.t, np.full(6000, 3.0), BASE.y)))


def _absurd(doc: Any, path: str = "") -> list[str]:
    """Entries of a JSON document that no diagnosis can mean: a share ("fraction") outside
    [0, 1.5], or a number beyond 1e100."""
    found: list[str] = []
    if isinstance(doc, dict):
        for k, v in doc.items():
            if isinstance(v, int | float) and not isinstance(v, bool) and (
                    abs(v) > 1e100 or ("fraction" in k and not -1e-9 <= v <= 1.5)):
                found.append(f"{path}{k}={v:.3g}")
            else:
                found += _absurd(v, f"{path}{k}.")
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            found += _absurd(v, f"{path}{i}.")
    return found


def judge_diag_sane(ws: Path, out: Outcome) -> tuple[str, str]:
    """A diagnosis of the base records: every share a share, every percentage printed below
    1000 %."""
    bad: list[str] = []
    with contextlib.suppress(ValueError):
        bad = _absurd(json.loads(out.stdout))
    bad += [m.group(0)[:40] for m in re.finditer(r"\d{4,}(?:\.\d+)? %", out.stdout)]
    if bad:
        return "silent-wrong", "absurd figures: " + ", ".join(bad[:3])
    return "sound-result", "figures in range"


def judge_floor_units(ws: Path, out: Outcome) -> tuple[str, str]:
    """A repeat floor measured in nm beside figures in um must not be presented as one."""
    rep = report_of(ws, out)
    floor = (rep.get("baselines") or {}).get("repeat_floor")
    if floor is not None and floor > 100 * BASE.rms and not report_warnings(rep):
        return "silent-wrong", f"repeat floor {floor:.3g} from a record in nm, reported in um"
    return "sound-result", f"repeat floor {floor}"


def judge_diag_noise(ws: Path, out: Outcome) -> tuple[str, str]:
    """A diagnosis scored on noise must not claim to close the gap."""
    try:
        rep = json.loads(out.stdout)
    except ValueError:
        return "sound-result", "no JSON"
    text = json.dumps(rep)[:200000].lower()
    if warned(out.stderr) or "warning" in text or "admissib" in text:
        return "sound-result", "the report warns"
    return "sound-result", "diagnosed (gap reported)"


def add_export_cases() -> None:
    """``hystid export``."""
    g = "export"
    base = copy_base("model.json", "train.csv")

    def exp(name: str, extra: list[str], hints: tuple[str, ...], **kw: Any) -> None:
        cli(name, ["export", "model.json", "--c", kw.pop("cdir", "cdir"), *extra], g,
            setup=kw.pop("setup", base), hints=hints, **kw)

    exp("export_plain", [], (), expect="ok", quick=True)
    exp("export_c_is_file", [], ("--c", "cfile"), cdir="cfile",
        setup=both(base, text_file("cfile", "mine")))
    exp("export_c_user_files", [], ("--c", "hystid_model"),
        setup=both(base, lambda ws: ((ws / "cdir").mkdir(),
                                     (ws / "cdir/hystid_model.c").write_text("/* mine */"))),
        quick=True)
    exp("export_c_proc", [], ("/proc", "--c"), cdir="/proc/hystid_audit")
    for v in ("1,0", "nan,1", "0,inf", "1"):
        exp(f"export_u_limits_{v}", [f"--u-limits={v}"], ("--u-limits",), quick=v == "nan,1")
    for v in ("-1", "0", "1000000000000"):
        exp(f"export_preview_{v}", [f"--preview={v}"], ("--preview",),
            quick=v == "1000000000000", expect="any" if v == "0" else "error")
    exp("export_smooth_2", ["--smooth", "2"], ("--smooth",))
    exp("export_smooth_1e9", ["--smooth", "1000000001"], ("--smooth",), quick=True)
    for v in ("0", "-1", "nan", "inf"):
        exp(f"export_rpem_sigma_{v}", [f"--rpem-sigma={v}"], ("--rpem-sigma",))
    exp("export_margin_nan", ["--margin", "nan"], ("--margin",))
    exp("export_rpem_record_missing", ["--rpem-record", "none.csv"], ("none.csv",))
    exp("export_rpem_record_two_samples", ["--rpem-record", "r2.csv"], ("r2.csv",),
        setup=both(base, text_file("r2.csv", "t,u,y\n0,1,1\n3.3333333333333335e-05,2,2\n")))
    exp("export_rpem_record_noise", ["--rpem-record", "rn.csv"], ("rn.csv",),
        setup=both(base, csv_arrays("rn.csv", lambda: (
            BASE.t, BASE.u, np.random.default_rng(22).normal(0, 1, 6000)))), expect="any")
    cli("export_pi_stage", ["export", "m.json", "--c", "cdir"], g,
        setup=model_doc(source="pi-stage.json"), expect="ok")
    cli("export_pi_poly", ["export", "m.json", "--c", "cdir"], g,
        setup=model_doc(source="pi-poly.json"), expect="ok")
    cli("export_mduhem", ["export", "m.json", "--c", "cdir"], g,
        setup=model_doc(source="mduhem.json"), expect="ok")  # exported since the C mduhem step


def add_fleet_cases() -> None:
    """``hystid fleet``."""
    g = "fleet"

    def recs(ws: Path) -> None:
        (ws / "recs").mkdir()
        copy_base("train.csv", "val.csv")(ws / "recs")

    fl = ["fleet", "identify"]
    cli("fleet_plain", [*fl, "recs", "--out", "res", "--workers", "1", "--quiet"], g,
        setup=recs, expect="ok", quick=True)
    cli("fleet_glob_nothing", [*fl, "recs/*.nothing", "--out", "res", "--workers", "1"], g,
        setup=recs, hints=("*.nothing", "recs"))
    cli("fleet_empty_folder", [*fl, "empty", "--out", "res", "--workers", "1"], g,
        setup=lambda ws: (ws / "empty").mkdir(), hints=("empty",))
    cli("fleet_table_missing_columns", [*fl, "t.csv", "--out", "res", "--workers", "1"], g,
        setup=both(recs, text_file("t.csv", "record,other\nrecs/train.csv,x\n")),
        hints=("t.csv", "train"), quick=True)
    cli("fleet_table_escaping_paths", [*fl, "t.csv", "--out", "res", "--workers", "1"], g,
        setup=both(recs, text_file("t.csv", "train,val\n../../../../etc/passwd,\n")),
        expect="any", judge=judge_fleet_failed_row)
    cli("fleet_table_same_record_twice", [*fl, "t.csv", "--out", "res", "--workers", "1"], g,
        setup=both(recs, text_file("t.csv", "train,val,name\nrecs/train.csv,recs/val.csv,a\n"
                                            "recs/val.csv,recs/train.csv,a\n")),
        hints=("name", "a"), expect="any", what="two rows with one name")
    for v in ("0", "-1", "1000000000"):
        cli(f"fleet_workers_{v}", [*fl, "recs", "--out", "res", f"--workers={v}"], g,
            setup=recs, hints=("--workers",), quick=v == "1000000000")
    for v in ("-1", str(2**70)):
        cli(f"fleet_seed_{v[:6]}", [*fl, "recs", "--out", "res", "--workers", "1",
                                    f"--seed={v}"], g, setup=recs, hints=("--seed",))
    for v in ("1", "nan"):
        cli(f"fleet_holdout_{v}", [*fl, "recs", "--out", "res", "--workers", "1",
                                   f"--holdout={v}"], g, setup=recs, hints=("--holdout",))
    cli("fleet_source_fifo", [*fl, "p.csv", "--out", "res", "--workers", "1"], g,
        setup=fifo("p.csv"), hints=("p.csv",), expect="any")
    cli("fleet_out_fifo", [*fl, "recs", "--out", "p", "--workers", "1"], g,
        setup=both(recs, fifo("p")), hints=("p", "--out"))
    cli("fleet_scheduler_unreachable", [*fl, "recs", "--out", "res", "--scheduler",
                                        "tcp://127.0.0.1:9"], g, setup=recs,
        hints=("--scheduler", "127.0.0.1"), quick=True)
    cli("fleet_scheduler_garbage", [*fl, "recs", "--out", "res", "--scheduler", "nonsense"],
        g, setup=recs, hints=("--scheduler",))
    cli("fleet_out_is_file", [*fl, "recs", "--out", "res", "--workers", "1"], g,
        setup=both(recs, text_file("res", "mine")), hints=("--out", "res"))
    cli("fleet_out_user_table", [*fl, "recs", "--out", "res", "--workers", "1"], g,
        setup=both(recs, lambda ws: ((ws / "res").mkdir(),
                                     (ws / "res/identify.csv").write_text("my,own\n1,2\n"))),
        hints=("res", "identify.csv"), quick=True,
        what="--out holds a CSV of the user's named identify.csv")
    cli("fleet_broken_record", [*fl, "recs", "--out", "res", "--workers", "1", "--quiet"], g,
        setup=both(recs, text_file("recs/broken.csv", "t,u,y\n0,1,x\n")), expect="any",
        judge=judge_fleet_failed_row)
    custom("fleet_out_inside_source_rerun", fleet_rerun_inside, g,
           what="--out inside the source folder, run twice: its own table read as a record?")
    cli("fleet_diagnose_plain", ["fleet", "diagnose", "recs", "--out", "res", "--workers", "1",
                                 "--quiet"], g, setup=recs, expect="ok")
    cli("fleet_diagnose_effects_bogus", ["fleet", "diagnose", "recs", "--out", "res",
                                         "--workers", "1", "--effects", "bogus"], g,
        setup=recs, hints=("--effects", "bogus"))


def judge_fleet_failed_row(ws: Path, out: Outcome) -> tuple[str, str]:
    """A fleet with a bad record: a failed row with its reason."""
    try:
        import pandas as pd
        table = pd.read_csv(ws / "res" / "identify.csv")
    except Exception as err:  # noqa: BLE001
        return "silent-wrong", f"status 0 but no result table ({err})"[:200]
    failed = table[table["status"] != "ok"]
    if len(failed) == 0:
        return "silent-wrong", "a broken record got an ok row"
    return "sound-result", f"failed row: {str(failed['error'].iloc[0])[:150]}"


def fleet_rerun_inside(ws: Path, timeout: float) -> dict:
    """Run a fleet whose --out lies in its source folder twice."""
    (ws / "recs").mkdir()
    copy_base("train.csv", "val.csv")(ws / "recs")
    argv = ["fleet", "identify", "recs", "--out", "recs/res", "--workers", "1", "--quiet"]
    first = run(argv, ws, timeout)
    second = run(argv, ws, timeout)
    outs = [first, second]
    row = bad_of(outs)
    if row:
        return row
    import pandas as pd
    try:
        names = list(pd.read_csv(ws / "recs/res/identify.csv")["name"])
    except Exception as err:  # noqa: BLE001
        return {"class": "clear-error" if second.status else "silent-wrong",
                "note": f"statuses {first.status}/{second.status}: {err}"[:200],
                "status": second.status, "seconds": first.seconds + second.seconds}
    own = [n for n in names if "identify" in str(n) or "res" in str(n)]
    cls = "silent-wrong" if own else "sound-result"
    return {"class": cls, "note": f"rows {names}"[:200], "status": second.status,
            "seconds": first.seconds + second.seconds}


def bad_of(outs: list[Outcome]) -> dict | None:
    """A row for the first run that hung or showed a traceback, if any."""
    for o in outs:
        if o.hung:
            return {"class": "hang", "note": "a run did not finish", "status": None,
                    "seconds": o.seconds}
        if TRACEBACK in o.stderr:
            return {"class": "traceback", "note": o.stderr.strip().splitlines()[-1][:200],
                    "status": o.status, "seconds": o.seconds}
    return None


def add_demo_cases() -> None:
    """``hystid demo``."""
    g = "demo"
    for v in ("0.001", "0", "nan", "-1", "601", "1e-300"):
        cli(f"demo_seconds_{v}", ["demo", f"--seconds={v}", "--out", "d", "--quiet"], g,
            hints=("--seconds",), quick=v == "0.001", expect="any" if v == "0.001" else
            "error")
    for v in ("-1", "1.5"):
        cli(f"demo_seed_{v}", ["demo", "--seconds", "0.05", f"--seed={v}", "--out", "d",
                               "--quiet"], g, hints=("--seed",))
    for v in ("-1", "nan", "1e6"):
        cli(f"demo_noise_{v}", ["demo", "--seconds", "0.05", f"--noise={v}", "--out", "d",
                                "--quiet"], g, hints=("--noise",),
            expect="any" if v == "1e6" else "error",
            judge=judge_demo_noise if v == "1e6" else None)
    cli("demo_out_exists", ["demo", "--seconds", "0.05", "--out", "d", "--quiet"], g,
        setup=lambda ws: ((ws / "d").mkdir(), (ws / "d/report.json").write_text("mine")),
        hints=("--out", "d"), quick=True)
    cli("demo_out_is_file", ["demo", "--seconds", "0.05", "--out", "d", "--quiet"], g,
        setup=text_file("d", "mine"), hints=("--out", "d"))
    cli("demo_plain", ["demo", "--seconds", "0.1", "--out", "d", "--quiet"], g, expect="ok")


def judge_demo_noise(ws: Path, out: Outcome) -> tuple[str, str]:
    """A demo drowned in noise (1 m): its report must not look good."""
    text = out.stdout + out.stderr
    if warned(text) or "not" in text.lower():
        return "sound-result", first_warning(out) or "says it is not better"
    return "sound-result", "a summary of a noisy run (the errors show it)"


# --------------------------------------------------------------------------- concurrency
def concurrent(argv_a: list[str], argv_b: list[str], gap: float,
               setup: Callable[[Path], None] | None = None,
               during: Callable[[Path], None] | None = None,
               protect: tuple[str, ...] = ()) -> Callable[[Path, float], dict]:
    """Two commands started ``gap`` seconds apart (or one, and ``during`` doing something to
    its output meanwhile): both claiming success for one output is an overwrite, unless both
    were given ``--force`` (then replacing is what was asked for)."""
    def call(ws: Path, timeout: float) -> dict:
        if setup:
            setup(ws)
        a, ta = start(argv_a, ws)
        time.sleep(gap)
        if during is not None:
            during(ws)
            before = {p: (ws / p).read_bytes() for p in protect}
            oa = finish(a, ta, timeout)
            outs = [oa]
            row = bad_of(outs)
            if row:
                return row
            lost = [p for p, b in before.items()
                    if not (ws / p).exists() or (ws / p).read_bytes() != b]
            if lost:
                return {"class": "overwrite", "note": f"replaced {lost} (status {oa.status})",
                        "status": oa.status, "seconds": oa.seconds}
            return {"class": "sound-result" if oa.status == 0 else "clear-error",
                    "note": error_line(oa.stderr)[:200] if oa.status else "kept the user's file",
                    "status": oa.status, "seconds": oa.seconds}
        b, tb = start(argv_b, ws)
        oa, ob = finish(a, ta, timeout), finish(b, tb, timeout)
        row = bad_of([oa, ob])
        if row:
            return row
        if oa.status == 0 and ob.status == 0 and "--force" in argv_a and "--force" in argv_b:
            return {"class": "sound-result", "note": "both forced: both exited 0, the later "
                                                     "replaced the earlier's result as asked",
                    "status": 0, "seconds": max(oa.seconds, ob.seconds)}
        if oa.status == 0 and ob.status == 0:
            return {"class": "overwrite", "note": "both runs exited 0: the later replaced the "
                                                  "earlier's result", "status": 0,
                    "seconds": max(oa.seconds, ob.seconds)}
        loser = ob if ob.status else oa
        return {"class": "clear-error", "note": f"statuses {oa.status}/{ob.status}: "
                                                f"{error_line(loser.stderr)[:180]}",
                "status": loser.status, "seconds": max(oa.seconds, ob.seconds)}
    return call


def add_concurrency_cases() -> None:
    """Two runs writing one output, and a file appearing in --out meanwhile."""
    g = "concurrency"
    base = copy_base("train.csv", "val.csv", "model.json")
    idr = ["identify", "train.csv", "--quiet", "--out", "rep"]
    custom("two_identify_one_out", concurrent(idr, idr, 0.4, setup=base), g, quick=True)
    custom("two_identify_one_out_forced", concurrent([*idr, "--force"], [*idr, "--force"], 0.4,
                                                     setup=base), g,
           what="both forced: replacing is what was asked for")
    custom("two_simulate_one_out", concurrent(
        ["simulate", "--seconds", "2", "--seed", "0", "--out", "s.csv", "--quiet"],
        ["simulate", "--seconds", "2", "--seed", "1", "--out", "s.csv", "--quiet"], 0.3), g,
        quick=True)
    custom("two_compensate_one_out", concurrent(
        ["compensate", "model.json", "--scan", "triangle:50:2", "--seconds", "2", "--out",
         "c.csv", "--quiet"],
        ["compensate", "model.json", "--scan", "sine:50:2", "--seconds", "2", "--out", "c.csv",
         "--quiet"], 0.3, setup=base), g)
    custom("two_export_one_dir", concurrent(["export", "model.json", "--c", "cdir"],
                                            ["export", "model.json", "--c", "cdir"], 0.2,
                                            setup=base), g)
    custom("two_demo_one_out", concurrent(["demo", "--seconds", "0.1", "--out", "d", "--quiet"],
                                          ["demo", "--seconds", "0.1", "--seed", "1", "--out",
                                           "d", "--quiet"], 0.4), g)

    def recs(ws: Path) -> None:
        (ws / "recs").mkdir()
        copy_base("train.csv", "val.csv")(ws / "recs")
    fl = ["fleet", "identify", "recs", "--out", "res", "--workers", "1", "--quiet"]
    custom("two_fleets_one_out", concurrent(fl, fl, 1.0, setup=recs), g, quick=True)
    custom("two_diagnose_one_out", concurrent(
        ["diagnose", "train.csv", "--quiet", "--time-budget", "0", "--out", "dg"],
        ["diagnose", "train.csv", "--quiet", "--time-budget", "0", "--out", "dg"], 0.5,
        setup=base), g)

    def user_writes_into_out(ws: Path) -> None:
        (ws / "rep").mkdir(exist_ok=True)
        (ws / "rep/model.json").write_text("the user's own model, written meanwhile\n")
    custom("file_appears_in_out", concurrent(
        ["identify", "train.csv", "--quiet", "--model", "auto", "--out", "rep"], [], 0.8,
        setup=base, during=user_writes_into_out, protect=("rep/model.json",)), g, quick=True)

    def user_writes_sim(ws: Path) -> None:
        (ws / "s.csv").write_text("the user's data\n")
    custom("file_appears_at_sim_out", concurrent(
        ["simulate", "--seconds", "3", "--seed", "0", "--out", "s.csv", "--quiet"], [], 0.4,
        during=user_writes_sim, protect=("s.csv",)), g)


# --------------------------------------------------------------------------- the API
def _rec(n: int | None = None, **kw: Any) -> Any:
    from hystid.records import Record
    n = len(BASE.u) if n is None else n
    return Record(u=BASE.u[:n].copy(), y=BASE.y[:n].copy(), fs=FS, **kw)


def _val() -> Any:
    from hystid.records import Record
    return Record(u=BASE.uv.copy(), y=BASE.yv.copy(), fs=FS, name="val")


def _model() -> Any:
    from hystid.modelfile import load_model
    return load_model(BASE.dir / "model.json")


def _ident(*args: Any, **kw: Any) -> Any:
    from hystid.identify import identify
    return identify(*args, **kw)


def _summary(res: Any) -> str:
    """A short summary of an identification result."""
    m = getattr(res, "model", res)
    params = getattr(m, "params", None)
    return f"{type(m).__name__} {params}"[:200]


def add_api_cases() -> None:
    """The public Python API."""
    g = "api"
    from hystid.compensate import compensate
    from hystid.diagnose import diagnose
    from hystid.modelfile import load_model
    from hystid.records import Record, load_record

    def a(name: str, call: Callable[[Path], Any], hints: tuple[str, ...] = (), **kw: Any
          ) -> None:
        api(name, call, g, hints=hints, **kw)

    # identify
    a("identify_none", lambda ws: _ident(None), ("record",), quick=True)
    a("identify_path_string", lambda ws: (copy_base("train.csv")(ws),
                                         _summary(_ident("train.csv")))[1], ("record",))
    a("identify_ndarray", lambda ws: _ident(np.zeros((100, 2))), ("record",), quick=True)
    a("identify_method_bogus", lambda ws: _ident(_rec(), method="bogus"), ("method", "bogus"))
    a("identify_structure_int", lambda ws: _ident(_rec(), structure=3), ("structure",),
      quick=True)
    a("identify_structure_text", lambda ws: _ident(_rec(), structure="n1a=1"),
      ("structure", "n1a"))
    a("identify_model_bogus", lambda ws: _ident(_rec(), model="bogus"), ("model", "bogus"))
    a("identify_mduhem_online", lambda ws: _ident(_rec(), "online", model="mduhem"),
      ("mduhem", "online", "method"))
    a("identify_theta0_text", lambda ws: _ident(_rec(), theta0="x"), ("theta0",))
    a("identify_unknown_setting", lambda ws: _ident(_rec(), bogus_setting=1),
      ("bogus_setting",), quick=True)
    a("identify_progress_not_callable", lambda ws: _summary(_ident(_rec(), progress=5)),
      ("progress",))
    a("identify_two_samples", lambda ws: _summary(_ident(_rec(2))), ("record", "sample"),
      quick=True)
    a("identify_online_two_samples", lambda ws: _summary(_ident(_rec(2), "online")),
      ("record", "sample"))
    a("identify_ekf_ten_samples", lambda ws: _summary(_ident(_rec(10), "ekf")),
      ("record", "sample"))
    a("identify_eria_constant", lambda ws: _summary(_ident(Record(
        u=np.full(6000, 2.0), y=BASE.y.copy(), fs=FS), "eria")), ("input", "constant"))
    a("identify_fs_tiny", lambda ws: _summary(_ident(Record(u=BASE.u.copy(), y=BASE.y.copy(),
                                                            fs=1e-300))),
      ("fs", "rate"), expect="any")
    a("identify_auto_online_pi", lambda ws: _summary(_ident(_rec(3000), "online", model="pi")),
      (), expect="ok")
    # Record
    a("record_empty", lambda ws: Record(u=[], y=[], fs=1.0), ("empty", "u"))
    a("record_nan", lambda ws: Record(u=[0.0, np.nan, 1.0], y=[0, 1, 2], fs=1.0), ("u", "nan",
                                                                                      "finite"))
    a("record_fs_zero", lambda ws: Record(u=[0, 1, 2], y=[0, 1, 2], fs=0), ("fs",), quick=True)
    a("record_fs_string", lambda ws: Record(u=[0, 1, 2], y=[0, 1, 2], fs="30k"), ("fs",))
    a("record_2d", lambda ws: Record(u=np.zeros((3, 2)), y=np.zeros((3, 2)), fs=1.0), ("u",))
    a("record_strings", lambda ws: Record(u=["a", "b"], y=[1, 2], fs=1.0), ("u",))
    a("record_bigint", lambda ws: Record(u=[2**70, 0, 1], y=[0, 1, 2], fs=1.0), ("u",),
      expect="any")
    a("record_complex", lambda ws: Record(u=[1j, 2, 3], y=[0, 1, 2], fs=1.0), ("u", "complex"))
    a("record_units_none", lambda ws: repr(Record(u=[0, 1, 2], y=[0, 1, 2], fs=1.0,
                                                  units=None)), ("units",))
    a("record_units_numbers", lambda ws: repr(Record(u=[0, 1, 2], y=[0, 1, 2], fs=1.0,
                                                     units={"u": 1, "y": 2})), ("units",),
      expect="any")
    a("record_name_none", lambda ws: repr(Record(u=[0, 1, 2], y=[0, 1, 2], fs=1.0, name=None)),
      ("name",), expect="any")
    a("record_int_index", lambda ws: _rec()[3], ("index", "slice"))
    a("record_step_slice", lambda ws: _rec()[::2], ("step", "slice"))
    # load_record
    a("load_record_none", lambda ws: load_record(None), ("path",), quick=True)
    a("load_record_int", lambda ws: load_record(123), ("path", "123"))
    a("load_record_bytes_path", lambda ws: (copy_base("train.csv")(ws),
                                           repr(load_record(b"train.csv")))[1],
      ("path", "train.csv"), expect="any")
    a("load_record_missing", lambda ws: load_record("none.csv"), ("none.csv",))
    a("load_record_directory", lambda ws: ((ws / "d.csv").mkdir(), load_record("d.csv"))[1],
      ("d.csv",))
    a("load_record_fifo", lambda ws: (os.mkfifo("p.csv"), load_record("p.csv"))[1],
      ("p.csv",), quick=True)
    a("load_record_columns_unknown", lambda ws: (copy_base("train.csv")(ws), load_record(
        "train.csv", columns={"u": "nope"}))[1], ("nope",))
    a("load_record_columns_range", lambda ws: (csv_variant("r.csv", header=None)(ws),
                                              load_record("r.csv", fs=FS,
                                                          columns={"u": -1, "y": 99}))[1],
      ("99", "-1", "column"))
    a("load_record_columns_bool", lambda ws: (csv_variant("r.csv", header=None)(ws),
                                             load_record("r.csv", fs=FS,
                                                         columns={"u": True, "y": 2}))[1],
      ("column", "True"))
    a("load_record_columns_not_mapping", lambda ws: (copy_base("train.csv")(ws), load_record(
        "train.csv", columns="u=1,y=2"))[1], ("columns",))
    a("load_record_fs_negative", lambda ws: (copy_base("train.csv")(ws),
                                            load_record("train.csv", fs=-1))[1], ("fs",))
    a("load_record_fs_string", lambda ws: (copy_base("train.csv")(ws),
                                          load_record("train.csv", fs="30k"))[1], ("fs",))
    a("load_record_units_none", lambda ws: (copy_base("train.csv")(ws), repr(
        load_record("train.csv", units={"u": None})))[1], ("units",))
    a("load_record_units_bad_role", lambda ws: (copy_base("train.csv")(ws), repr(
        load_record("train.csv", units={"z": "V"})))[1], ("units", "z"))
    a("load_record_name_number", lambda ws: (copy_base("train.csv")(ws), repr(
        load_record("train.csv", name=5)))[1], ("name",), expect="any")
    # load_model
    a("load_model_none", lambda ws: load_model(None), ("path",), quick=True)
    a("load_model_directory", lambda ws: ((ws / "m.json").mkdir(), load_model("m.json"))[1],
      ("m.json",))
    a("load_model_fifo", lambda ws: (os.mkfifo("m.json"), load_model("m.json"))[1],
      ("m.json",))
    a("load_model_deep", lambda ws: (model_doc(raw=lambda s: "{\"a\":" * 100_000 + "1" +
                                               "}" * 100_000)(ws), load_model("m.json"))[1],
      ("m.json",), quick=True)
    a("load_model_pole_on_circle", lambda ws: (model_doc(both_edit(
        setp("params.a21", -2.0), setp("params.a22", 1.0)))(ws), load_model("m.json"))[1],
      ("m.json",))
    a("load_model_record", lambda ws: (copy_base("train.csv")(ws),
                                      load_model("train.csv"))[1], ("train.csv",))
    # simulate
    a("simulate_none", lambda ws: _model().simulate(None), ("u",), quick=True)
    a("simulate_empty", lambda ws: _model().simulate([]), ("u", "empty"))
    a("simulate_nan", lambda ws: _model().simulate([0.0, np.nan, 1.0]), ("u", "finite", "nan"),
      quick=True)
    a("simulate_2d", lambda ws: _model().simulate(np.zeros((10, 2))), ("u",))
    a("simulate_strings", lambda ws: _model().simulate(["a", "b"]), ("u",))
    a("simulate_1e300", lambda ws: float(np.max(np.abs(_model().simulate(
        np.full(100, 1e300)).y))), ("u",), expect="error",
      what="an input of 1e300 V: an error or a warning")
    a("simulate_x0_garbage", lambda ws: _model().simulate(BASE.u[:100], x0="garbage"),
      ("x0",))
    a("simulate_unknown_state", lambda ws: _model().simulate(BASE.u[:100], bogus=1),
      ("bogus",))
    a("simulate_pi_p0_garbage", lambda ws: load_model(BASE.dir / "pi-stage.json").simulate(
        BASE.u[:100], p0="garbage"), ("p0",))
    a("simulate_beyond_envelope", lambda ws: float(np.max(_model().simulate(
        BASE.u * 3).y)), (), judge=judge_api_value(lambda v: "no warning for 3x the envelope"))
    a("simulate_ints", lambda ws: float(np.max(_model().simulate(
        np.round(BASE.u).astype(np.int64)).y)), (), expect="any")
    # compensate
    yref = lambda: BASE.y[:3000].copy()  # noqa: E731
    a("comp_empty", lambda ws: compensate(_model(), []), ("y_ref", "empty"))
    a("comp_nan", lambda ws: compensate(_model(), np.r_[yref()[:10], np.nan]),
      ("y_ref", "finite", "nan"), quick=True)
    a("comp_2d", lambda ws: compensate(_model(), np.zeros((10, 2))), ("y_ref",))
    a("comp_limits_inverted", lambda ws: compensate(_model(), yref(), u_limits=(5, 1)),
      ("u_limits",), quick=True)
    a("comp_limits_nan", lambda ws: compensate(_model(), yref(), u_limits=(np.nan, 1)),
      ("u_limits",))
    a("comp_limits_text", lambda ws: compensate(_model(), yref(), u_limits="0,5"),
      ("u_limits",))
    a("comp_margin_negative", lambda ws: compensate(_model(), yref(), margin=-1),
      ("margin",))
    a("api_comp_margin_nan", lambda ws: compensate(_model(), yref(), margin=float("nan")),
      ("margin",))
    a("comp_preview_negative", lambda ws: compensate(_model(), yref(), preview=-5),
      ("preview",))
    a("comp_preview_huge", lambda ws: compensate(_model(), yref(), preview=10**9),
      ("preview",), quick=True)
    a("comp_preview_float", lambda ws: compensate(_model(), yref(), preview=2.5),
      ("preview",))
    a("comp_mode_bogus", lambda ws: compensate(_model(), yref(), compensation="bogus"),
      ("compensation", "bogus"))
    a("comp_anchor_bogus", lambda ws: compensate(_model(), yref(), anchor="x"), ("anchor",))
    a("comp_reference_lead_negative", lambda ws: compensate(_model(), yref(),
                                                            reference_lead=-3),
      ("reference_lead",))
    a("comp_duhem_bound_zero", lambda ws: compensate(_model(), yref(), duhem_bound=0),
      ("duhem_bound",))
    a("comp_model_none", lambda ws: compensate(None, yref()), ("model",))
    a("comp_model_path", lambda ws: compensate(str(BASE.dir / "model.json"), yref()),
      ("model",))
    a("comp_reference_1e300", lambda ws: float(np.max(np.abs(compensate(
        _model(), yref() * 1e300).u))), ("y_ref",), expect="error")
    a("comp_pi_stage_plain", lambda ws: float(np.max(np.abs(compensate(
        load_model(BASE.dir / "pi-stage.json"), yref()).u))), (), expect="ok")
    # diagnose
    a("diag_none", lambda ws: diagnose(None, progress=False), ("train",), quick=True)
    a("diag_val_string", lambda ws: diagnose(_rec(), val="val.csv", progress=False),
      ("val",))
    a("api_diag_effects_bogus", lambda ws: diagnose(_rec(), _val(), effects=["bogus"],
                                                progress=False), ("bogus",))
    a("diag_effects_string", lambda ws: diagnose(_rec(), _val(), effects="creep",
                                                 progress=False), ("effects",))
    a("diag_holdout_1p5", lambda ws: diagnose(_rec(), holdout=1.5, progress=False),
      ("holdout",))
    a("diag_max_rounds_negative", lambda ws: diagnose(_rec(), _val(), max_rounds=-1,
                                                      progress=False), ("max_rounds",))
    a("api_diag_alpha_nan", lambda ws: diagnose(_rec(), _val(), alpha=float("nan"),
                                            progress=False), ("alpha",))
    a("diag_model_string", lambda ws: diagnose(_rec(), _val(), model="m.json",
                                               progress=False), ("model",))
    a("diag_two_samples", lambda ws: diagnose(_rec(2), progress=False), ("train", "sample",
                                                                        "record"))
    a("diag_initial_bogus", lambda ws: diagnose(_rec(), _val(), initial="bogus",
                                                progress=False), ("initial",))
    a("diag_progress_not_callable", lambda ws: repr(diagnose(_rec(), _val(), progress=5,
                                                             time_budget=0))[:80],
      ("progress",), expect="any")
    a("diag_pi_model", lambda ws: diagnose(_rec(), _val(), model=load_model(
        BASE.dir / "pi-stage.json"), progress=False, time_budget=0), ("model", "pi"),
      expect="any")
    # invariance from Python
    a("api_online_units_kV_nm", lambda ws: api_invariance("online", 1e-3, 1e3), (),
      expect="any", judge=judge_invariance)
    a("api_batch_input_offset_1e5", lambda ws: api_invariance("batch", 1.0, 1.0, 1e5), (),
      expect="any", judge=judge_invariance, quick=True)
    a("api_pi_stage_input_offset_1e5", lambda ws: api_invariance("batch", 1.0, 1.0, 1e5,
                                                                 model="pi-stage"), (),
      expect="any", judge=judge_invariance)


def api_invariance(method: str, su: float, sy: float, off: float = 0.0,
                   model: str = "duhem") -> dict:
    """Identify the base record and a scaled / shifted copy; the two models' predictions on
    the validation input, put back into the base units."""
    from hystid.identify import identify
    from hystid.records import Record
    a = identify(Record(u=BASE.u.copy(), y=BASE.y.copy(), fs=FS), method, model=model)
    b = identify(Record(u=BASE.u * su + off, y=BASE.y * sy, fs=FS,
                        units={"u": "kV" if su != 1 else "V", "y": "nm" if sy != 1 else "um"}),
                 method, model=model)
    pa = simulate_quiet(a.model, BASE.uv)
    pb = simulate_quiet(b.model, BASE.uv * su + off) / sy
    d = (pb - pb[0]) - (pa - pa[0])
    return {"diff": float(np.sqrt(np.mean(d ** 2))),
            "rms_a": float(np.sqrt(np.mean((pa - BASE.yv) ** 2))),
            "warnings_b": [str(w) for w in (b.warnings if hasattr(b, "warnings") else [])]}


def judge_invariance(ws: Path, result: dict) -> tuple[str, str]:
    """The scaled / shifted record must identify the same model."""
    v = result["value"]
    note = f"prediction difference {v['diff']:.3g} RMS (model's own error {v['rms_a']:.3g})"
    if not np.isfinite(v["diff"]) or v["diff"] > 0.25 * max(v["rms_a"], 1e-12):
        return "silent-wrong", note
    return "sound-result", note


def build_cases() -> None:
    """Fill :data:`CASES`."""
    add_record_file_cases()
    add_identify_option_cases()
    add_semantic_cases()
    add_simulate_cases()
    add_model_file_cases()
    add_compensate_cases()
    add_diagnose_cases()
    add_export_cases()
    add_fleet_cases()
    add_demo_cases()
    add_concurrency_cases()
    add_api_cases()
    names = [c.name for c in CASES]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise SystemExit(f"duplicate case names: {sorted(dup)}")


# =========================================================================== the run
def run_case(case: Case, root: Path, timeout: float) -> dict:
    """Run one case in its own folder and classify it."""
    ws = root / case.name
    ws.mkdir()
    if case.setup is not None:
        case.setup(ws)
    limit = case.timeout or timeout
    row: dict[str, Any] = {"name": case.name, "group": case.group, "kind": case.kind,
                           "what": case.what}
    if case.kind == "cli":
        before = snapshot(ws)
        out = run(case.argv or [], ws, limit)
        cls, note = classify_cli(case, ws, out, changed_files(before, ws))
        row.update(command="hystid " + " ".join(_show(a) for a in case.argv or []),
                   status=out.status, traceback=TRACEBACK in out.stderr,
                   seconds=round(out.seconds, 2), stderr_tail=out.stderr.strip()[-600:])
    elif case.kind == "api":
        before = snapshot(ws)
        out, result = run_api(case, ws, limit)
        lost = changed_files(before, ws)
        if lost and not out.hung:
            cls, note = "overwrite", f"changed or removed: {lost[:5]}"
        else:
            cls, note = classify_api(case, ws, out, result)
        row.update(command=f"api:{case.name}", status=out.status,
                   traceback=cls == "traceback", seconds=round(out.seconds, 2),
                   exception=None if not result or result["ok"] else
                   f"{result['type']}: {result['message'][:300]}",
                   warnings=(result or {}).get("warnings", [])[:3])
    else:
        got = case.call(ws, limit)
        cls, note = got["class"], got["note"]
        row.update(command=f"custom:{case.name}", status=got.get("status"),
                   traceback=cls == "traceback", seconds=round(got.get("seconds", 0.0), 2))
    row.update({"class": cls, "note": note, "vague": note.startswith("[vague]")
                or "[names neither" in note})
    return row


def _show(arg: str) -> str:
    """An argument as a shell would need it."""
    if arg and all(c.isalnum() or c in "-_./=:,+" for c in arg):
        return arg
    return "'" + arg.replace("'", "'\\''").replace("\n", "\\n").replace("\x1b", "\\e") + "'"


def main(argv: list[str] | None = None) -> int:
    """Run the audit, print the table, write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", help="JSON file for the results")
    parser.add_argument("--timeout", type=float, default=60.0,
                        help="seconds after which a case counts as a hang (default 60)")
    parser.add_argument("--quick", action="store_true", help="the quick subset only")
    parser.add_argument("--only", default="", help="cases whose name or group holds this text")
    parser.add_argument("--keep", help="keep the workspace in this folder")
    parser.add_argument("--list", action="store_true", help="list the cases and stop")
    args = parser.parse_args(argv)
    if not (args.timeout > 0 and math.isfinite(args.timeout)):
        parser.error("--timeout must be a positive number of seconds")

    build_cases()
    chosen = [c for c in CASES if (c.quick or not args.quick)
              and (args.only in c.name or args.only == c.group)]
    if args.list:
        for c in chosen:
            print(f"{c.group:18} {c.name}")
        print(f"{len(chosen)} cases")
        return 0
    root = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="hystid-audit-"))
    root.mkdir(parents=True, exist_ok=True)
    if any(root.iterdir()):
        parser.error(f"--keep {root}: the folder must be empty")
    t0 = time.perf_counter()
    print(f"workspace {root}; making the base records and models", file=sys.stderr)
    make_base(root)
    rows = []
    for i, case in enumerate(chosen, 1):
        row = run_case(case, root, args.timeout)
        rows.append(row)
        flag = "" if row["class"] in ("clear-error", "sound-result") else "  <=="
        print(f"[{i:3}/{len(chosen)} {time.perf_counter() - t0:6.0f} s] {row['class']:12} "
              f"{case.name}{flag}", file=sys.stderr, flush=True)
        if not args.keep and row["class"] not in BAD:
            shutil.rmtree(root / case.name, ignore_errors=True)
    counts = {c: sum(r["class"] == c for r in rows) for c in CLASSES}
    print_table(rows, counts)
    total = time.perf_counter() - t0
    print(f"\n{len(rows)} cases in {total:.0f} s: " +
          ", ".join(f"{counts[c]} {c}" for c in CLASSES) +
          f"; {sum(r['vague'] for r in rows)} vague messages")
    if args.out:
        payload = {"cases": rows, "counts": counts, "seconds": round(total, 1),
                   "quick": args.quick, "timeout": args.timeout, "hystid": HYSTID,
                   "workspace": str(root)}
        Path(args.out).write_text(json.dumps(payload, indent=1, default=str))
        print(f"wrote {args.out}")
    if not args.keep:
        print(f"cases that went wrong are kept in {root}" if any(
            r["class"] in BAD for r in rows) else "", end="")
        if not any(r["class"] in BAD for r in rows):
            shutil.rmtree(root, ignore_errors=True)
    return 1 if any(r["class"] in BAD for r in rows) else 0


def print_table(rows: list[dict], counts: dict[str, int]) -> None:
    """The results: every case that went wrong in full, then counts per group."""
    groups = sorted({r["group"] for r in rows})
    print("| group | cases | " + " | ".join(CLASSES) + " |")
    print("|---|---|" + "---|" * len(CLASSES))
    for grp in groups:
        sel = [r for r in rows if r["group"] == grp]
        print(f"| {grp} | {len(sel)} | " + " | ".join(
            str(sum(r["class"] == c for r in sel)) for c in CLASSES) + " |")
    print(f"| all | {len(rows)} | " + " | ".join(str(counts[c]) for c in CLASSES) + " |")
    print("\n| case | class | status | s | note |")
    print("|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['name']} | {r['class']} | {r['status']} | {r['seconds']} | "
              f"{str(r['note']).replace('|', '/')[:160]} |")


if __name__ == "__main__":
    sys.exit(main())
