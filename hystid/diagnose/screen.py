"""Screening of candidate effects and the held-out significance test.

**Screen.** A candidate's *signature* is the change its new parameters make in the simulated
output, with the part that the parameters already in the model can absorb projected out (their
Jacobian, by finite differences). Its screen score is the share of the train residual that this
signature matches (a score test: one Gauss-Newton step from the current model). Parameters that
are undefined at zero strength (creep time constant, mode frequency and damping, slew limit,
dead time) are scanned on a grid, seeded by the localisation (spectral peaks); the best grid
points are the refit's starts. A signature that the model absorbs almost entirely (less than
:data:`MIN_SEPARATION` of its norm left) means the records cannot show that effect: the candidate
is reported as not excited.

**Test.** A refit is accepted only when it lowers the held-out squared error significantly for
coloured residuals: the loss differential ``d(k) = e_base(k)^2 - e_cand(k)^2`` is tested with a
block t-test (the mean of ``d`` over contiguous blocks, Student t with ``blocks - 1`` degrees of
freedom: robust to any dependence shorter than a block) and with a Diebold-Mariano statistic
whose variance is a Newey-West HAC estimate (Bartlett kernel, Andrews' AR(1) plug-in bandwidth).
The larger of the two one-sided p-values is used.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import stats

from ..model import DuhemSandwich
from .correlation import correlation
from .effects import EFFECTS, MAX_DELAY, N_SLOTS
from .parametrisation import Parametrisation
from .refit import FitData, simulate_fit_data

__all__ = [
    "MIN_SEPARATION",
    "ScreenResult",
    "compare_losses",
    "effect_names_check",
    "hac_variance",
    "screen",
    "zero_vector",
]

#: Smallest share of a signature's norm left after projecting out the model's own directions
#: for the records to show the effect.
MIN_SEPARATION = 0.01

#: Dead times scanned by the screen, in samples (the refit goes on from the best).
DELAY_GRID = (0.1, 0.3, 0.6, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0, 32.0)

_HINTS = {
    "creep": "the input needs level changes held longer than the creep time",
    "creep_2tau": "the input needs level changes held longer than the creep times",
    "creep_log": "the input needs level changes held over several decades of time",
    "mode_series": "the input needs broadband content near the mode",
    "loop_level": "the input needs loops at several levels",
    "slew_input": "the input needs fast steps",
    "output_curve": "the output needs a wide range",
    "drift": "the record needs to be longer",
    "extra_mode": "the input needs broadband content near the mode",
    "delay": "the input needs fast changes",
    "asymmetry": "the input needs ascending and descending branches of different shape",
    "asymmetry_input": "the input needs ascending and descending branches of different shape",
    "slew_limit": "the input needs fast steps",
    "saturation": "the input needs a wide range of levels",
    "offset": "the record starts at its measured level, which fixes the offset",
}


@dataclass
class ScreenResult:
    """Screen of one candidate.

    Attributes
    ----------
    name : str
        Effect name.
    score : float
        Share of the train residual matched by the best signature (0..1).
    separation : float
        Largest share of a signature's norm that the model cannot absorb.
    excited : bool
        Whether the records can show the effect (``separation >= MIN_SEPARATION``).
    starts : list of ndarray
        Effect vectors to start the refit from, best first.
    message : str
        Why the candidate is not excited, or empty.
    profile : ndarray or None
        Orthonormal basis of the output directions of the current model's own parameters
        (rows: the train samples scored), shared by the candidates of one screen: the refit's
        effect-only stage profiles them out (:func:`hystid.diagnose.refit.refit`).
    """

    name: str
    score: float
    separation: float
    excited: bool
    starts: list[np.ndarray] = field(default_factory=list)
    message: str = ""
    profile: np.ndarray | None = field(default=None, repr=False)


def _jacobian(model: DuhemSandwich, phi: np.ndarray, active: Sequence[str], data: FitData,
              step_scale: float, w1_scale: float) -> np.ndarray:
    """Finite-difference Jacobian of the simulated output w.r.t. the search coordinates."""
    par = Parametrisation(model, active, len(data.u) / data.fs, step_scale, w1_scale)
    z0 = par.to_z(model.theta, phi)
    lo, hi = par.bounds()
    work = DuhemSandwich(model.theta.copy(), model.structure, fs=model.fs)
    theta, ph = par.to_values(z0, phi)
    work.theta = theta
    y0 = simulate_fit_data(work, ph, data)[2][data.weight].copy()
    cols = []
    for i in range(len(z0)):
        h = 1e-6 * max(1.0, abs(z0[i]))
        z = z0.copy()
        z[i] = z0[i] + h if z0[i] + h <= hi[i] else z0[i] - h
        theta, ph = par.to_values(z, phi)
        work.theta = theta
        yi = simulate_fit_data(work, ph, data)[2][data.weight]
        cols.append((yi - y0) / (z[i] - z0[i]))
    return np.column_stack(cols)


def _orth(J: np.ndarray) -> np.ndarray:
    """Orthonormal basis of the column space of a tall matrix (from its small Gram matrix;
    a tall SVD is slow with a threaded BLAS on a busy machine)."""
    J = J[:, np.all(np.isfinite(J), axis=0)]
    norms = np.linalg.norm(J, axis=0)
    J = J[:, norms > 0] / norms[norms > 0]
    if J.shape[1] == 0:
        return np.zeros((J.shape[0], 0))
    w, V = np.linalg.eigh(J.T @ J)
    keep = w > 1e-12 * w.max()
    Q = J @ (V[:, keep] / np.sqrt(w[keep]))
    # one re-orthogonalisation pass for accuracy
    w2, V2 = np.linalg.eigh(Q.T @ Q)
    return Q @ (V2 / np.sqrt(w2))


def _lstsq(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Least squares for a few columns by the normal equations (with a tiny ridge)."""
    H = A.T @ A
    return np.linalg.solve(H + 1e-14 * np.trace(H) * np.eye(len(H)) + 1e-300 * np.eye(len(H)),
                           A.T @ b)


def screen(
    model: DuhemSandwich,
    phi: np.ndarray,
    active: Sequence[str],
    data: FitData,
    candidates: Sequence[str],
    *,
    step_scale: float,
    w1_scale: float = 1.0,
    peaks_hz: Sequence[float] = (),
    n_starts: int = 2,
    pool: Executor | None = None,
) -> dict[str, ScreenResult]:
    """Screen candidate effects against the train residual of the current model.

    Parameters
    ----------
    model : DuhemSandwich
        Current nominal parameters.
    phi : ndarray
        Current effect vector (effects already accepted).
    active : sequence of str
        Effects already in the model (their parameters count as the model's own directions).
    data : FitData
        Train record.
    candidates : sequence of str
        Effects to screen.
    step_scale : float
        Largest ``|dw1|`` per sample of the current simulation (scale of the slew grid).
    w1_scale : float
        Largest ``|w1|`` of the current simulation (scale of the saturation coefficient).
    peaks_hz : sequence of float
        Frequencies where the localisation found narrow-band excess (mode grid seeds).
    n_starts : int
        Refit starts kept per candidate.
    pool : Executor, optional
        Threads to screen the candidates in, side by side (in this thread by default); the
        result is the same.

    Returns
    -------
    dict
        :class:`ScreenResult` by effect name.
    """
    fs = data.fs
    T = len(data.u) / fs
    dt = 1.0 / fs
    y = data.y[data.weight]
    y0 = simulate_fit_data(model, phi, data)[2][data.weight].copy()
    e = y - y0
    ee = float(e @ e)
    Q = _orth(_jacobian(model, phi, active, data, step_scale, w1_scale))

    def simulation_on(own: FitData):
        def sim(ph):
            return simulate_fit_data(model, ph, own)[2][own.weight].copy()
        return sim

    def with_(**slots):
        ph = np.array(phi, float)
        for k, v in slots.items():
            ph[int(k[1:])] = v
        return ph

    def grid(name: str, sim: Callable[[np.ndarray], np.ndarray]):
        """Yield (directions N x k, function beta -> effect vector start)."""
        h = 1e-4
        if name in ("creep", "creep_2tau", "creep_log"):
            lo_tau = 0.5 / fs if name == "creep_log" else max(3 * dt, 5e-3)
            hi_tau = 0.2 * T if name == "creep_log" else 2 * T
            for tau in np.geomspace(lo_tau, max(hi_tau, 2 * lo_tau), 10):
                if name == "creep_log":
                    D = (sim(with_(s17=h, s18=tau)) - y0) / h
                    yield D[:, None], (lambda b, tau=tau: with_(
                        s17=float(np.clip(b[0], 0.0, .5)), s18=tau))
                    continue
                D = (sim(with_(s0=h, s1=tau)) - y0) / h
                if name == "creep":
                    yield D[:, None], (lambda b, tau=tau: with_(
                        s0=float(np.clip(b[0], 0.0, .5)), s1=tau))
                    continue
                D2 = (sim(with_(s15=h, s16=10 * tau)) - y0) / h
                yield np.column_stack([D, D2]), (lambda b, tau=tau: with_(
                    s0=float(np.clip(b[0], 1e-4, .5)), s1=tau,
                    s15=float(np.clip(b[1], 1e-4, .5)), s16=10 * tau))
        elif name == "drift":
            cols = [(sim(with_(**{k: h})) - y0) / h for k in ("s2", "s3", "s21")]
            yield np.column_stack(cols), (lambda b: with_(s2=b[0], s3=b[1], s21=b[2]))
        elif name in ("extra_mode", "mode_series"):
            slot = "s4" if name == "extra_mode" else "s19"
            freqs = list(np.geomspace(max(20.0 / T, 50.0), 0.45 * fs, 32)) + list(peaks_hz)
            for f in freqs:
                if not 0 < f < 0.49 * fs:
                    continue
                for zeta in (0.01, 0.05):
                    D = (sim(with_(**{slot: h}, s5=f, s6=zeta)) - y0) / h
                    yield D[:, None], (lambda b, f=f, z=zeta, slot=slot: with_(
                        **{slot: float(np.clip(b[0], -1, 1))}, s5=f, s6=z))
        elif name == "delay":
            for d in DELAY_GRID:
                if d > MAX_DELAY - 1:
                    continue
                D = sim(with_(s7=d)) - y0
                # a dead time is not linear in its size: the grid point itself is the start
                yield D[:, None], (lambda b, d=d: with_(s7=d))
        elif name in ("asymmetry", "asymmetry_input"):
            keys = ("s8", "s9", "s13") if name == "asymmetry" else ("s27", "s28", "s29")
            cols = [(sim(with_(**{k: h})) - y0) / h for k in keys]
            yield np.column_stack(cols), (lambda b, keys=keys: with_(
                **{k: float(np.clip(v, -.5, .5)) for k, v in zip(keys, b, strict=True)}))
        elif name == "loop_level":
            hl = h / w1_scale
            cols = [(sim(with_(**{k: hl})) - y0) / hl for k in ("s14", "s20")]
            lim = 0.5 / w1_scale
            yield np.column_stack(cols), (lambda b: with_(
                s14=float(np.clip(b[0], -lim, lim)), s20=float(np.clip(b[1], -lim, lim))))
        elif name == "slew_limit":
            for rel in (1.05, 1.2, 1.5, 2.0, 3.0, 5.0):
                inv = rel / (fs * step_scale)
                D = sim(with_(s10=inv)) - y0
                yield D[:, None], (lambda b, inv=inv: with_(s10=inv))
        elif name == "slew_input":
            steps = np.abs(np.diff(data.u))
            du = float(np.max(steps)) if steps.size else 1.0
            du = du or 1.0
            # limits scaled by the largest input step and, when a few outlying steps (a jump,
            # an end glitch) dwarf the rest, by the steps of the input's ordinary motion
            typical = float(np.quantile(steps, 0.99)) if steps.size else du
            rels = [1.05, 1.2, 1.5, 2.0, 3.0, 5.0]
            if 0 < typical < du / 5.0:
                rels += [r * du / typical for r in (1.05, 1.5, 3.0)]
            for rel in rels:
                inv = rel / (fs * du)
                D = sim(with_(s22=inv)) - y0
                yield D[:, None], (lambda b, inv=inv: with_(s22=inv))
        elif name == "output_curve":
            centre = 0.5 * (float(np.max(y0)) + float(np.min(y0)))
            span = float(np.ptp(y0)) or 1.0
            cols = [(sim(with_(**{k: h}, s25=centre, s26=span)) - y0) / h for k in ("s23", "s24")]
            yield np.column_stack(cols), (lambda b, c=centre, sp=span: with_(
                s23=float(np.clip(b[0], -.3, .3)), s24=float(np.clip(b[1], -.2, .2)),
                s25=c, s26=sp))
        elif name == "saturation":
            hc = h / w1_scale**2
            D = (sim(with_(s11=hc)) - y0) / hc
            yield D[:, None], (lambda b: with_(s11=float(np.clip(b[0] * w1_scale**2, -0.25,
                                                                 2.0)) / w1_scale**2))
        elif name == "offset":
            D = (sim(with_(s12=phi[12] + h)) - y0) / h
            yield D[:, None], (lambda b: with_(s12=float(phi[12] + b[0])))
        else:  # pragma: no cover - names are checked by the caller
            raise ValueError(name)

    def screen_one(name: str, own: FitData) -> tuple[ScreenResult, np.ndarray | None]:
        """The candidate's best score over its grid, its starts and best directions."""
        scored = []
        sep = 0.0
        for D, start in grid(name, simulation_on(own)):
            D = np.where(np.isfinite(D), D, 0.0)
            Dp = D - Q @ (Q.T @ D)
            nD = np.linalg.norm(D, axis=0)
            if np.all(nD == 0):
                continue
            # the effect shows when any of its directions that moves the output at all is
            # left by the model (a parameter whose base coefficient is zero, f1 of an
            # asymmetry with f1 = 0, moves nothing and says nothing of the others)
            moves = nD > 1e-9 * nD.max()
            sep = max(sep, float(np.max(np.linalg.norm(Dp[:, moves], axis=0) / nD[moves])))
            b = _lstsq(Dp, e)
            fitted = Dp @ b
            score = float(fitted @ fitted / ee) if ee > 0 else 0.0
            # by Frisch-Waugh-Lovell, b is also the effect's coefficient in the joint step
            scored.append((score, start(b), Dp))
        if not scored:
            return ScreenResult(name, 0.0, 0.0, False, [],
                                f"{name}: its parameters do not change the simulated output "
                                f"on these records; {_HINTS[name]}"), None
        scored.sort(key=lambda s: -s[0])
        excited = sep >= MIN_SEPARATION
        msg = "" if excited else (
            f"{name}: the records cannot show it: the model absorbs "
            f"{100 * (1 - sep):.2f} % of its signature; {_HINTS[name]}")
        starts = [s[1] for s in scored[:n_starts + (1 if name == "delay" else 0)]]
        return ScreenResult(name, scored[0][0], sep, excited, starts, msg, Q), scored[0][2]

    if pool is None:
        found = [screen_one(name, data) for name in candidates]
    else:  # each candidate on a simulation workspace of its own
        jobs = [pool.submit(screen_one, name, replace(data)) for name in candidates]
        found = [job.result() for job in jobs]
    out = {r.name: r for r, _ in found}
    best_dirs = {r.name: d for r, d in found if d is not None}
    # creep and drift are told apart only by input level changes
    if ("creep" in best_dirs and "drift" in best_dirs
            and max(out["creep"].score, out["drift"].score) > 0.01):
        A, B = _orth(best_dirs["creep"]), _orth(best_dirs["drift"])
        if A.shape[1] and B.shape[1]:
            cos = float(np.linalg.svd(A.T @ B, compute_uv=False).max())
            if cos > 0.995:
                for k in ("creep", "drift"):
                    r = out[k]
                    r.message = (r.message + "; " if r.message else "") + (
                        f"creep and drift cannot be told apart on these records (signatures "
                        f"{100 * cos:.1f} % alike): the input needs level changes")
    return out


def hac_variance(d: np.ndarray, demean: bool = True) -> tuple[float, int]:
    """Newey-West long-run variance of ``d`` and the bandwidth used.

    Bartlett kernel with Andrews' (1991) AR(1) plug-in bandwidth
    ``L = 1.1447 (a N)^(1/3)``, ``a = 4 rho^2 / ((1 - rho)^2 (1 + rho)^2)``, at most ``N / 4``.
    With ``demean=False`` the series is taken as already centred (a score with known mean 0).

    Parameters
    ----------
    d : ndarray
        The series.
    demean : bool
        Subtract the mean first.

    Returns
    -------
    tuple
        The long-run variance (float) and the bandwidth in samples (int).
    """
    x = np.asarray(d, float)
    x = x - np.mean(x) if demean else x
    n = len(x)
    with np.errstate(over="ignore", invalid="ignore"):
        g0 = float(x @ x) / n
        rho = float(np.clip((x[1:] @ x[:-1]) / (x @ x), -0.99, 0.99)) if g0 else 0.0
    if not (np.isfinite(g0) and np.isfinite(rho)):  # overflowed: no finite variance
        return float("inf"), 0
    if n < 8 or g0 == 0:
        return g0, 0
    a = 4 * rho**2 / ((1 - rho) ** 2 * (1 + rho) ** 2)
    L = int(min(np.ceil(1.1447 * (a * n) ** (1 / 3)), n // 4))
    gam = correlation(x, None, L) / n
    w = 1.0 - np.arange(1, L + 1) / (L + 1)
    return float(max(gam[0] + 2 * np.sum(w * gam[1:]), gam[0] * 1e-6)), L


def compare_losses(
    e_base: Sequence[np.ndarray], e_cand: Sequence[np.ndarray], *, blocks: int = 12
) -> dict[str, float]:
    """One-sided test that the candidate's held-out squared error is smaller than the base's.

    With ``delta = e_base - e_cand`` (the difference of the two simulations) the loss
    differential is ``d = e_base^2 - e_cand^2 = 2 e_base delta - delta^2``, so
    ``mean(d) > 0`` exactly when the coefficient ``beta`` of ``e_base = beta delta + eps``
    exceeds 1/2 (the candidate's output is nearer the data than the base's; a forecast
    encompassing form of the Diebold-Mariano test). Given the two fitted models, ``delta`` is
    fixed and the randomness is in ``eps``: the variance of ``sum(delta eps)`` is estimated
    with a Newey-West HAC estimator (Bartlett kernel, Andrews' bandwidth) and, separately,
    from contiguous block sums (Student t with ``blocks - 1`` degrees of freedom); both are
    valid for coloured residuals and the larger p-value is kept. The unconditional
    Diebold-Mariano statistic on ``d`` (HAC variance) is reported too.

    Parameters
    ----------
    e_base, e_cand : sequence of ndarray
        Held-out errors of the two models, one array per held-out segment.
    blocks : int
        Number of contiguous blocks of the block test.

    Returns
    -------
    dict
        ``p_value``, ``beta``, ``t_hac``, ``p_hac``, ``hac_lag``, ``t_block``, ``p_block``,
        ``dm``, ``p_dm``, ``rms_base``, ``rms_cand`` and ``rel_reduction``
        (``1 - rms_cand / rms_base``).
    """
    eb = [np.asarray(a, float) for a in e_base]
    ec = [np.asarray(b, float) for b in e_cand]
    deltas = [a - b for a, b in zip(eb, ec, strict=True)]
    Eb, Ec, De = np.concatenate(eb), np.concatenate(ec), np.concatenate(deltas)
    n = len(Eb)
    with np.errstate(over="ignore", invalid="ignore"):
        mb, mc = float(np.mean(Eb**2)), float(np.mean(Ec**2))
    out = {"rms_base": float(np.sqrt(mb)), "rms_cand": float(np.sqrt(mc)),
           "rel_reduction": float(1.0 - np.sqrt(mc / mb)) if 0 < mb < np.inf and mc < np.inf
           else 0.0}
    with np.errstate(over="ignore", invalid="ignore"):
        dd = float(De @ De)
    if dd == 0 or not (np.isfinite(dd) and np.isfinite(Eb).all() and np.isfinite(Ec).all()):
        # no difference, or a simulation that overflowed: nothing to test, nothing accepted
        out.update({"p_value": 1.0, "beta": 0.0, "t_hac": 0.0, "p_hac": 1.0, "hac_lag": 0,
                    "t_block": 0.0, "p_block": 1.0, "dm": 0.0, "p_dm": 0.5})
        return out
    beta = float(Eb @ De / dd)
    # statistic: sum(delta (e_base - delta/2)) = (beta - 1/2) sum(delta^2)
    num = float(De @ Eb - 0.5 * dd)
    var = 0.0
    lag = 0
    for a, de in zip(eb, deltas, strict=True):
        eps = a - beta * de
        v, L = hac_variance(de * eps, demean=False)
        var += v * len(a)
        lag = max(lag, L)
    t_hac = num / np.sqrt(var) if var > 0 else (np.inf if num > 0 else -np.inf)
    p_hac = float(stats.norm.sf(t_hac))
    # block version: block sums of delta (e_base - delta / 2) around their share of the total
    x = De * (Eb - beta * De) + (beta - 0.5) * De * De
    t_block, p_block = _block_t_centered(x, De * De, beta, blocks)
    d = Eb**2 - Ec**2
    v_dm = sum(hac_variance(a**2 - b**2)[0] * len(a) for a, b in zip(eb, ec, strict=True))
    dm = float(d.mean() / np.sqrt(v_dm / n**2)) if v_dm > 0 else 0.0
    out.update({"p_value": max(p_hac, p_block), "beta": beta, "t_hac": float(t_hac),
                "p_hac": p_hac, "hac_lag": int(lag), "t_block": t_block, "p_block": p_block,
                "dm": dm, "p_dm": float(stats.norm.sf(dm))})
    return out


def _block_t_centered(x: np.ndarray, w: np.ndarray, beta: float, blocks: int):
    """Block t-test of ``sum(x) > 0`` where ``x = delta eps + (beta - 1/2) delta^2``: the
    spread comes from the block sums of ``delta eps`` alone (``w = delta^2`` carries the
    fixed part)."""
    B = int(min(blocks, max(2, len(x) // 50)))
    fixed = (beta - 0.5) * w
    noise = np.array([c.sum() for c in np.array_split(x - fixed, B)])
    sd = float(np.sqrt(np.sum(noise**2) * B / (B - 1)))
    total = float(x.sum())
    if sd == 0:
        t = np.inf if total > 0 else (-np.inf if total < 0 else 0.0)
    else:
        t = total / sd
    return float(t), float(stats.t.sf(t, B - 1))


def zero_vector() -> np.ndarray:
    """An effect vector with every effect off.

    Returns
    -------
    ndarray
        The effect vector, all zero.
    """
    return np.zeros(N_SLOTS)


def effect_names_check(names: Sequence[str]) -> tuple[str, ...]:
    """Validate a list of candidate names.

    Parameters
    ----------
    names : sequence of str
        Effect or family names.

    Returns
    -------
    tuple of str
        The names, checked.
    """
    names = tuple(names)
    bad = [n for n in names if n not in EFFECTS]
    if bad:
        raise ValueError(f"effects: unknown {bad}; expected names from {tuple(EFFECTS)}")
    if len(set(names)) != len(names):
        raise ValueError(f"effects: duplicate names in {names}")
    return names
