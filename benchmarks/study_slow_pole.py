"""Stage A: the ``pi-stage`` model's slow L2 pole and the rest level after a move.

The default model on measured stage A (``pi-stage``, identified on ``prbn_1``) holds in L2 a real
pole near 0.2 Hz with a zero near 0.4 Hz: a DC gain about twice the gain above 1 Hz, fitted on
1 s of excitation. This study puts three figures side by side:

1. **The records' own rest outputs.** Each record rests about 1 s before its excitation, at
   -5.34 V (PRBN, triangles) or -1.78 V (sines): the mean output over each rest, and the change
   between the two levels (every pair of records across them; the sensor's zero moves between
   records by a few tens of nm, which spreads the pairs).
2. **What the model predicts for that move**: the output change ``t`` seconds after a step of
   the input from -5.34 V to -1.78 V (run from the model's rest, as every held-out record is).
3. **The same member with its slow pole bounded**: L2's denominator searched as a quadratic
   (its reflection coefficients, as every fit does) times ``(1 - rho z^-1)`` with
   ``|rho| <= exp(-1 / (fs tau_max))``, ``tau_max`` a fifth of the training record's
   excitation: a pole the record can identify. Held-out RMS on every other record, zeroed on
   each record's output at rest (:func:`hystid.baselines.compare`'s scoring) and as placed
   (the model's own rest and offset).

The bounded parametrisation exists only here, patched into the PI fit for the study
(:class:`BoundedRealPole`); the project's fits keep the plain reflection coefficients.

    OPENBLAS_NUM_THREADS=1 python benchmarks/study_slow_pole.py
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import warnings
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from _common import table, write_json

from hystid.baselines import rest_zero, simulate_from_rest
from hystid.identify import constraints, pi_batch
from hystid.identify.members import member
from hystid.records import load_record

STAGE_A = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "stageA"
TRAIN = "prbn_1"
HELD = ("prbn_2", "sine50_1", "sine50_2", "tri50_1", "tri50_2")
#: The slowest time constant allowed, as a share of the training record's excitation.
SPAN_SHARE = 0.2
#: Seconds after the step at which the model's level change is read.
AFTER = (0.1, 1.0, 3.0)


class BoundedRealPole(constraints.Reflections):
    """Search coordinates with each denominator of three coefficients factored as
    ``(1 + c1 z^-1 + c2 z^-2)(1 - rho z^-1)``: ``[k1, k2, rho]``, ``|rho| <= rho_max``."""

    rho_max = 1.0 - 1e-6

    def to_z(self, theta: np.ndarray) -> np.ndarray:
        z = np.array(theta, float)
        for g in self.groups:
            if len(g) != 3:
                z[g] = np.clip(constraints.poly_to_reflection(theta[g]), -constraints.K_MAX,
                               constraints.K_MAX)
                continue
            roots = np.roots(np.r_[1.0, theta[g]])
            real = roots[np.abs(roots.imag) < 1e-9].real
            rho = float(real[np.argmax(real)]) if real.size else 0.0
            quad = np.real(np.poly(np.delete(roots, np.argmin(np.abs(roots - rho)))))
            z[g[:2]] = np.clip(constraints.poly_to_reflection(quad[1:]), -constraints.K_MAX,
                               constraints.K_MAX)
            z[g[2]] = np.clip(rho, -self.rho_max, self.rho_max)
        return z

    def to_theta(self, z: np.ndarray, jacobian: bool = True):
        theta, dtheta = np.array(z, float), np.eye(self.n)
        for g in self.groups:
            if len(g) != 3:
                theta[g], dtheta[np.ix_(g, g)] = constraints.reflection_to_poly(z[g])
                continue
            c, dc = constraints.reflection_to_poly(z[g[:2]])
            rho = z[g[2]]
            q = np.r_[1.0, c]
            theta[g] = np.convolve(q, [1.0, -rho])[1:]
            d = np.array([[1.0, 0.0], [-rho, 1.0], [0.0, -rho]])
            dtheta[np.ix_(g, g[:2])] = d @ dc
            dtheta[g, g[2]] = -q
        return theta, (dtheta if jacobian else None)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = super().bounds()
        for g in self.groups:
            if len(g) == 3:
                lo[g[2]], hi[g[2]] = -self.rho_max, self.rho_max
        return lo, hi


@contextlib.contextmanager
def bounded_pole(rho_max: float) -> Iterator[None]:
    """The PI fit searches with :class:`BoundedRealPole` inside the block."""
    cls = type("Bounded", (BoundedRealPole,), {"rho_max": rho_max})
    saved = pi_batch.Reflections
    pi_batch.Reflections = cls
    try:
        yield
    finally:
        pi_batch.Reflections = saved


def _rest_end(rec) -> int:
    """Samples of the leading rest."""
    return int(np.flatnonzero(np.abs(rec.u - rec.u[0]) > 0.0)[0])


def _rest(rec) -> tuple[float, float]:
    """Input level and mean output over the leading rest."""
    return float(rec.u[0]), float(np.mean(rec.y[:_rest_end(rec)]))


def _scores(model, recs) -> tuple[list[float], list[float]]:
    zeroed, placed = [], []
    for rec in recs:
        p = simulate_from_rest(model, rec.u, check=False)
        zeroed.append(float(np.sqrt(np.mean((p + rest_zero(p, rec) - rec.y) ** 2))))
        placed.append(float(np.sqrt(np.mean((p - rec.y) ** 2))))
    return zeroed, placed


def _real_poles_hz(model) -> list[float]:
    return [float(abs(np.log(abs(p))) * model.fs / (2 * np.pi)) for p in model.L2.poles()
            if abs(p.imag) < 1e-9]


def measure() -> dict:
    """Rest levels, the model's predicted move and the bounded refit.

    Returns
    -------
    dict
        ``rest`` (per record: input level, output), ``rest_change`` (min, max over pairs),
        ``predicted`` (change after each of :data:`AFTER`), and per fit its real L2 poles
        and held-out RMS zeroed and as placed.
    """
    if not STAGE_A.exists():
        return {"error": f"{STAGE_A} is absent"}
    recs = {n: load_record(STAGE_A / f"{n}.csv") for n in (TRAIN, *HELD)}
    rest = {n: _rest(r) for n, r in recs.items()}
    low = [v for (u, v) in rest.values() if u < -3.0]
    high = [v for (u, v) in rest.values() if u > -3.0]
    pairs = [b - a for a, b in itertools.product(low, high)]
    train = recs[TRAIN]
    spec = member("pi-stage")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        free = spec.fit(train).model
        span = (train.n - _rest_end(train)) / train.fs  # the excitation
        tau_max = SPAN_SHARE * span
        with bounded_pole(float(np.exp(-1.0 / (train.fs * tau_max)))):
            bounded = spec.fit(train).model
    u0, u1 = rest[TRAIN][0], rest["sine50_1"][0]
    n0 = int(train.fs)
    step = np.r_[np.full(n0, u0), np.full(int(max(AFTER) * train.fs) + 1, u1)]
    y = simulate_from_rest(free, step, check=False)
    predicted = [float(y[n0 + int(t * train.fs) - 1] - y[n0 - 1]) for t in AFTER]
    held = [recs[n] for n in HELD]
    fits = {}
    for label, model in (("pi-stage", free), (f"pi-stage, tau <= {tau_max:.2g} s", bounded)):
        zeroed, placed = _scores(model, held)
        fits[label] = {"real_poles_hz": _real_poles_hz(model), "zeroed": zeroed,
                       "placed": placed}
    return {"rest": rest, "rest_change": [min(pairs), max(pairs)], "levels": [u0, u1],
            "after": list(AFTER), "predicted": predicted, "tau_max": tau_max, "fits": fits,
            "held": list(HELD)}


def render(payload: dict) -> str:
    """The figures as Markdown.

    Parameters
    ----------
    payload : dict
        From :func:`measure`.

    Returns
    -------
    str
    """
    if "error" in payload:
        return f"Not measured: {payload['error']}."
    u0, u1 = payload["levels"]
    lo, hi = payload["rest_change"]
    moves = ", ".join(f"{1e3 * d:.0f} nm after {t:g} s"
                      for t, d in zip(payload["after"], payload["predicted"], strict=True))
    rows = []
    for label, f in payload["fits"].items():
        poles = ", ".join(f"{p:.2g}" for p in f["real_poles_hz"])
        rows.append([f"`{label}` (real L2 pole {poles} Hz)",
                     *(f"{1e3 * z:.0f} / {1e3 * p:.0f}"
                       for z, p in zip(f["zeroed"], f["placed"], strict=True))])
    return "\n".join([
        f"Rest outputs: the records resting at {u1:g} V sit {1e3 * lo:.0f}-{1e3 * hi:.0f} nm "
        f"above those resting at {u0:g} V; the `pi-stage` model predicts {moves} for that move.",
        "", table(rows, ["held-out RMS [nm], zeroed / as placed", *payload["held"]])])


def main() -> None:
    """Run, print, write ``study_slow_pole.json``."""
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    payload = measure()
    print(render(payload))
    print(f"-> {write_json('study_slow_pole', payload)}")


if __name__ == "__main__":
    main()
