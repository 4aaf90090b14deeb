"""A moving-horizon re-solve run as a job of bounded steps, beside an on-line recursion.

An on-line identifier with a moving horizon re-solves the last ``window`` samples now and then
(Levenberg-Marquardt with an arrival cost). Run inside the ``update()`` call it falls on, the
re-solve stalls that call for its whole cost (milliseconds) while every other call takes
microseconds: beside a control loop a sample is then late. :class:`HorizonSolve` runs the same
re-solve in steps of at most :data:`SLICE` simulated samples: first the chunks that leave the
window are folded into the arrival cost, then the window is solved, then the model is run at the
estimate over the samples that arrived meanwhile, a whole slice of them at a time (one compiled
call, not one per sample). The identifier gives it a fixed share of work
per processed sample (:meth:`HorizonSolve.advance`) and takes its estimate at the next chunk
boundary (:meth:`HorizonSolve.result` does the work left, if any). The work per sample is thus
bounded when the share suffices, and the estimates depend neither on the share nor on time:
``update()`` sample by sample and ``partial_fit`` over a block give the same ones.

The re-solve, in the identifier's search coordinates ``phi`` (``J = d yhat / d phi``, the errors
``e = y - yhat``; NaN errors left out)::

    cost(phi) = sum_k e_k(phi)^2 + (phi - phi_a)' R_a (phi - phi_a)
    A         = J' J + R_a,   g = J' e - R_a (phi - phi_a)
    trial     = phi + (A + damping diag(A))^-1 g

from each start; a trial outside the admissible set is refused without a simulation, a trial
that lowers the cost accepted (the damping divided by 3), any other refused (times 4); a start
stops after ``iterations`` trials or once a step gains less than :data:`RTOL` of the cost; the
lowest cost over the starts is the estimate. The normal equations are formed once per accepted
step, a slice of rows at a time.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass

import numpy as np

from ..spd import spd_inverse, spd_solve

__all__ = ["SLICE", "HorizonResult", "HorizonSolve", "covariance", "drain", "fold_steps",
           "normal_steps", "run_steps", "solve_information"]

#: Samples simulated (or rows added to the normal equations) in one step of the job.
SLICE = 100
#: Cost of a row of the normal equations relative to a simulated sample (measured: ``J' J`` of
#: 10 000 x 25 rows in 0.31 ms, their simulation with gradients 1.4 ms).
NORMAL_ROW = 0.25

#: A start's iterations stop when an accepted step lowered the cost by less than this share of
#: it, or when the next step's predicted decrease is below it (the damping only grows then).
#: Measured on the Bouc-Wen look-alike of stage A (6 s record): every re-solve ran its 12
#: iterations, each step lowering the window's cost by 1e-4-1e-3 of it; stopped at 1e-4 the
#: on-line identification took 2.9 s instead of 5.4 s with the same held-out figures (to 0.1
#: nm); on stage A the re-solves end earlier on refused trials and nothing changed.
RTOL = 1e-4

#: Cost of a trial step (its linear solve and admissibility test) in simulated samples (measured:
#: 10-20 us; most trials on stage A are refused without a simulation).
TRIAL = 100.0

#: ``simulate(phi, state, u, y, J, err)``: run the model over ``u`` from ``state`` (updated in
#: place), writing the gradient rows ``J`` and the errors ``err`` (NaN where ``y`` is not finite).
Simulate = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                    None]
_Steps = Generator[float, None, tuple]


def drain(steps: _Steps):
    """Run a generator of steps to its end and return its value.

    Parameters
    ----------
    steps : generator
        Yields the work of each step, returns the value.

    Returns
    -------
    object
        The generator's return value.
    """
    while True:
        try:
            next(steps)
        except StopIteration as stop:
            return stop.value


def solve_information(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``A x = b`` for an information matrix ``A`` (symmetric, positive definite): compiled
    Cholesky (:func:`hystid.spd.spd_solve`), numpy's LU when that finds it not positive
    definite.

    Parameters
    ----------
    A : ndarray
        Square matrix.
    b : ndarray
        Right-hand side.

    Returns
    -------
    ndarray
    """
    x = spd_solve(A, b)
    return np.linalg.solve(A, b) if x is None else x


def covariance(information: np.ndarray) -> np.ndarray:
    """The inverse of an information matrix (symmetric, positive definite): compiled Cholesky
    (:func:`hystid.spd.spd_inverse`), numpy's when that finds it not positive definite.

    Parameters
    ----------
    information : ndarray
        Square matrix.

    Returns
    -------
    ndarray
    """
    P = spd_inverse(information)
    return np.linalg.inv(information) if P is None else P


def run_steps(simulate: Simulate, phi: np.ndarray, state: np.ndarray, u: np.ndarray,
              y: np.ndarray, out: tuple[np.ndarray, np.ndarray] | None = None) -> _Steps:
    """The model run over ``u`` at ``phi`` from ``state`` (copied), a slice of at most
    :data:`SLICE` samples per step; returns ``(err, J, state at the end)``.

    Parameters
    ----------
    simulate : callable
        :data:`Simulate`.
    phi : ndarray
        Search coordinates.
    state : ndarray
        The model's state before ``u[0]``.
    u, y : ndarray
        Input and output.
    out : tuple of ndarray, optional
        ``(J, err)`` to write into (``len(u)`` rows); new arrays by default.

    Returns
    -------
    generator
    """
    m = len(u)
    st = state.copy()
    J, err = out if out is not None else (np.empty((m, len(phi))), np.empty(m))
    for a in range(0, m, SLICE):
        b = min(m, a + SLICE)
        simulate(phi, st, u[a:b], y[a:b], J[a:b], err[a:b])
        yield float(b - a)
    return err, J, st


def normal_steps(J: np.ndarray, err: np.ndarray, A: np.ndarray, g: np.ndarray) -> _Steps:
    """``J' J`` and ``J' e`` added to ``A`` and ``g`` (in place), rows with a NaN error left
    out, a slice of :data:`SLICE` rows per step (the same sums whatever the caller's blocks);
    returns ``(A, g)``.

    Parameters
    ----------
    J, err : ndarray
        Gradient rows and errors.
    A, g : ndarray
        Sums to add to.

    Returns
    -------
    generator
    """
    for a in range(0, len(err), SLICE):
        Js, es = J[a:a + SLICE], err[a:a + SLICE]
        seen = np.isfinite(es)
        if not seen.all():
            Js, es = Js[seen], es[seen]
        A += Js.T @ Js
        g += Js.T @ es
        yield NORMAL_ROW * len(seen)
    return A, g


def fold_steps(simulate: Simulate, phi: np.ndarray, state: np.ndarray,
               arrival: tuple[np.ndarray, np.ndarray], u: np.ndarray, y: np.ndarray) -> _Steps:
    """A chunk that leaves the window, folded into the arrival cost linearised at ``phi``.

    Its cost ``|e - J d|^2`` is added to ``(d - d_a)' R_a (d - d_a)`` (``d = phi' - phi``) and
    the window then starts at the chunk's end, the model run with ``phi``. Returns
    ``((phi_a, R_a), state at the chunk's end)``.

    Parameters
    ----------
    simulate : callable
        :data:`Simulate`.
    phi : ndarray
        The estimate it is linearised at.
    state : ndarray
        The model's state at the chunk's start.
    arrival : tuple of ndarray
        ``(phi_a, R_a)`` before.
    u, y : ndarray
        The chunk.

    Returns
    -------
    generator
    """
    phi_a, R_a = arrival
    err, J, st = yield from run_steps(simulate, phi, state, u, y)
    JJ, Je = yield from normal_steps(J, err, np.zeros_like(R_a), np.zeros(len(phi)))
    R = R_a + JJ
    return (solve_information(R, R_a @ phi_a + JJ @ phi + Je), R), st


@dataclass
class HorizonResult:
    """The estimate of a finished re-solve.

    Attributes
    ----------
    phi : ndarray
        Search coordinates of the lowest cost found.
    state : ndarray
        The model's state, run with ``phi``, after the window and the samples fed since.
    information : ndarray
        ``J' J + R_a`` at ``phi`` over the window and the samples fed since (the inverse is
        the recursion's covariance).
    cost : float
        The cost at ``phi`` over the window.
    arrival : tuple of ndarray
        ``(phi_a, R_a)`` with the chunks that left the window folded in.
    start : ndarray
        The model's state at the window's start.
    """

    phi: np.ndarray
    state: np.ndarray
    information: np.ndarray
    cost: float
    arrival: tuple[np.ndarray, np.ndarray]
    start: np.ndarray


class HorizonSolve:
    """One moving-horizon re-solve (see the module docstring), run in bounded steps.

    First the chunks that leave the window are folded into the arrival cost (linearised at
    ``linearised_at``), then the window is solved, then the model is run at the estimate over
    the samples fed since the launch (:meth:`feed`), so that it takes over where the
    recursion is.

    Parameters
    ----------
    simulate : callable
        ``simulate(phi, state, u, y, J, err)`` (:data:`Simulate`); called on slices in order,
        the state carried from one to the next.
    admissible : callable
        ``admissible(trial, phi)``: whether a trial step from ``phi`` may be taken.
    chunks : sequence of tuple of ndarray
        The window's chunks ``(u, y)`` (normalised units), oldest first; the first
        ``leaving`` are folded into the arrival cost, the others are the window.
    state : ndarray
        The model's state at the first chunk's start (copied).
    arrival : tuple of ndarray
        ``(phi_a, R_a)``: the arrival cost's estimate and information.
    starts : sequence of ndarray
        Start vectors (duplicates are run once).
    iterations : int
        Levenberg-Marquardt trials per start.
    leaving : int
        Chunks folded into the arrival cost first.
    linearised_at : ndarray, optional
        The estimate they are folded at (required when ``leaving``).
    forget : callable, optional
        ``forget(arrival) -> arrival``, applied once the leaving chunks are folded and before
        the window is solved (an identifier that marginalises nuisance coordinates out of the
        arrival cost, so that the window alone fixes them).

    Attributes
    ----------
    solved : bool
        Whether the window has been solved (:attr:`result` may still lack samples fed).
    spent : float
        Work done so far, in simulated samples (rows of the normal equations count
        :data:`NORMAL_ROW`).
    """

    def __init__(self, simulate: Simulate, admissible: Callable[[np.ndarray, np.ndarray], bool],
                 chunks: Sequence[tuple[np.ndarray, np.ndarray]], state: np.ndarray,
                 arrival: tuple[np.ndarray, np.ndarray], starts: Sequence[np.ndarray],
                 iterations: int, leaving: int = 0,
                 linearised_at: np.ndarray | None = None,
                 forget: Callable[[tuple[np.ndarray, np.ndarray]],
                                  tuple[np.ndarray, np.ndarray]] | None = None) -> None:
        if leaving and linearised_at is None:
            raise ValueError("linearised_at: expected the estimate to fold the leaving chunks at")
        self.simulate, self.admissible = simulate, admissible
        self.leaving = list(chunks[:leaving])
        self._window = list(chunks[leaving:])
        self.state, self.arrival, self.linearised_at = state.copy(), arrival, linearised_at
        self.forget = forget
        self.starts: list[np.ndarray] = []
        for s in starts:
            if not any(np.array_equal(s, t) for t in self.starts):
                self.starts.append(np.array(s, dtype=float))
        self.iterations = int(iterations)
        self.solved = False
        self.spent = 0.0
        self._credit = 0.0
        self._job = self._solve()
        self._solution: HorizonResult | None = None
        self._fed = np.empty((2, 1024))  # samples fed: u, y ..
        self._n_fed = self._n_run = 0  # .. how many, and how many the model has run over
        self._rows: tuple[np.ndarray, np.ndarray] | None = None  # their (J, err) ..
        self._nrows = 0  # .. up to SLICE: whole slices are summed into the information

    # ----------------------------------------------------------------- copy and pickle
    def __getstate__(self) -> dict:
        """State for copy and pickle. A generator cannot be either: the re-solve is run to
        its solution first (its estimate is the same whenever that is done)."""
        if not self.solved:
            self.advance(math.inf)
        return {k: v for k, v in self.__dict__.items() if k != "_job"}

    def __setstate__(self, state: dict) -> None:
        """Restore a solved re-solve (see :meth:`__getstate__`)."""
        self.__dict__.update(state)
        self._job = None

    # ----------------------------------------------------------------- running
    def feed(self, u: np.ndarray, y: np.ndarray) -> None:
        """Samples that arrived after the launch (the model follows them once solved).

        Parameters
        ----------
        u, y : ndarray
            Input and output, normalised units.
        """
        m = len(u)
        if self._n_fed + m > self._fed.shape[1]:
            grown = np.empty((2, 2 * (self._n_fed + m)))
            grown[:, :self._n_fed] = self._fed[:, :self._n_fed]
            self._fed = grown
        self._fed[0, self._n_fed:self._n_fed + m] = u
        self._fed[1, self._n_fed:self._n_fed + m] = y
        self._n_fed += m

    def advance(self, work: float) -> bool:
        """Run steps worth ``work`` simulated samples (the surplus of a step is carried over):
        the re-solve's, then the samples fed.

        Parameters
        ----------
        work : float
            Work granted, in simulated samples.

        Returns
        -------
        bool
            :attr:`solved`.
        """
        self._credit += work
        while self._credit > 0.0 and not self.solved:
            try:
                step = next(self._job)
            except StopIteration as stop:
                self._solution = stop.value
                self.solved = True
                break
            self._credit -= step
            self.spent += step
        if self.solved:  # whole slices of the samples fed (one kernel call each)
            whole = (self._n_fed - self._n_run) // SLICE * SLICE
            if whole and self._credit > 0.0:
                self._follow(min(whole, SLICE * math.ceil(min(self._credit, whole) / SLICE)))
            if self._n_fed - self._n_run < SLICE:
                self._credit = 0.0
        return self.solved

    def _follow(self, most: float) -> None:
        """The model run at the estimate over at most ``most`` of the samples fed, its rows
        summed into the information a slice of :data:`SLICE` rows at a time."""
        sol = self._solution
        if self._rows is None:
            self._rows = (np.empty((SLICE, len(sol.phi))), np.empty(SLICE))
        left = int(min(self._n_fed - self._n_run, most))
        while left > 0:
            a, r = self._n_run, self._nrows
            m = min(left, SLICE - r)
            J, err = self._rows[0][r:r + m], self._rows[1][r:r + m]
            sol.state = drain(run_steps(self.simulate, sol.phi, sol.state, self._fed[0, a:a + m],
                                        self._fed[1, a:a + m], out=(J, err)))[2]
            self._n_run, self._nrows, left = a + m, r + m, left - m
            self._credit -= m
            self.spent += m
            if self._nrows == SLICE:
                self._sum_rows()

    def _sum_rows(self) -> None:
        """The followed rows not yet summed added to the information."""
        J, err = self._rows[0][:self._nrows], self._rows[1][:self._nrows]
        drain(normal_steps(J, err, self._solution.information, np.zeros(J.shape[1])))
        self._nrows = 0

    def result(self) -> HorizonResult:
        """Run the steps left, follow every sample fed and return the estimate.

        Returns
        -------
        HorizonResult
            The information holds the samples fed (their rows summed in slices of
            :data:`SLICE` from the launch, whatever the blocks they were fed in).
        """
        while not self.solved:
            self.advance(math.inf)
        if self._n_run < self._n_fed:
            self._follow(math.inf)
        if self._nrows:
            self._sum_rows()
        return self._solution

    # ----------------------------------------------------------------- the steps
    def _cost(self, phi: np.ndarray, err: np.ndarray) -> float:
        d = phi - self.phi_a
        e = err if np.isfinite(err).all() else err[np.isfinite(err)]
        return float(e @ e + d @ self.R_a @ d)

    def _run(self, phi: np.ndarray) -> _Steps:
        return run_steps(self.simulate, phi, self.state, self.u, self.y)

    def _normal(self, phi: np.ndarray, J: np.ndarray, err: np.ndarray) -> _Steps:
        """``A = J' J + R_a`` and ``g = J' e - R_a (phi - phi_a)``."""
        return normal_steps(J, err, self.R_a.copy(), -(self.R_a @ (phi - self.phi_a)))

    def _solve(self) -> _Steps:
        self.u = np.concatenate([c[0] for c in self._window])
        self.y = np.concatenate([c[1] for c in self._window])
        for u, y in self.leaving:
            self.arrival, self.state = yield from fold_steps(
                self.simulate, self.linearised_at, self.state, self.arrival, u, y)
        if self.forget is not None:
            self.arrival = self.forget(self.arrival)
        self.phi_a, self.R_a = self.arrival
        best = None
        for start in self.starts:
            phi = start.copy()
            err, J, st = yield from self._run(phi)
            f = self._cost(phi, err)
            damping = 1e-3
            A = g = None
            for _ in range(self.iterations):
                if A is None:  # the normal equations at phi, kept while trials are refused
                    A, g = yield from self._normal(phi, J, err)
                d = solve_information(A + damping * np.diag(np.diag(A)), g)
                yield TRIAL
                if 2.0 * (g @ d) - d @ A @ d <= RTOL * f:
                    break  # the step, and any more damped one, would gain next to nothing
                trial = phi + d
                if not self.admissible(trial, phi):
                    damping *= 4.0
                    continue
                err_t, J_t, st_t = yield from self._run(trial)
                f_t = self._cost(trial, err_t)
                if np.isfinite(f_t) and f_t < f:
                    converged = f - f_t <= RTOL * f
                    phi, err, J, st, f = trial, err_t, J_t, st_t, f_t
                    damping = max(damping / 3.0, 1e-9)
                    A = None
                    if converged:
                        break
                else:
                    damping *= 4.0
            if best is None or f < best[0]:
                best = (f, phi, err, J, st, A)
        f, phi, err, J, st, A = best
        if A is None:
            A, _ = yield from self._normal(phi, J, err)
        return HorizonResult(phi, st, A, f, self.arrival, self.state)
