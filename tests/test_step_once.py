"""The sandwich's step (eqs. 1, 7, 2) is written once, in :func:`hystid.kernels.step`.

The EKF's transition calls it (through :func:`hystid.kernels.step_sens_row`, which also gives
the Jacobian); the diagnosis' augmented kernel fuses it with the candidate effects. Both forms are
driven here with :func:`hystid.kernels.simulate_into` on the same random structures, parameters,
pasts and inputs, and must agree to 1e-12 relative, the way filterpy tests the two forms of its
Kalman filter against each other. A structure richer than the plain Duhem sandwich is refused
by both (:func:`hystid.validate.check_plain_duhem`).
"""

from __future__ import annotations

import numpy as np
import pytest

from hystid.diagnose import diagnose
from hystid.diagnose.effects import (
    EFFECTS,
    AugmentedSandwich,
    augmented_into,
    augmented_output,
    effect_vector,
)
from hystid.identify.ekf import KalmanIdentifier, state_sizes, transition
from hystid.kernels import simulate_into
from hystid.model import DuhemSandwich, InitialCondition, Structure
from hystid.reference import reference_model, reference_record
from hystid.validate import PLAIN_DUHEM_LAYOUT, check_plain_duhem

N = 3000  # samples of each run
FS = 30_000.0
RTOL = 1e-12


def _structures() -> list[Structure]:
    """The two corners of the orders and delays tested, the paper's, and random ones."""
    rng = np.random.default_rng(24)
    found = [Structure(0, 0, 0, 0, 0, 0, False), Structure(2, 2, 3, 2, 3, 2, True), Structure()]
    while len(found) < 14:
        s = Structure(int(rng.integers(0, 3)), int(rng.integers(0, 3)), int(rng.integers(0, 4)),
                      int(rng.integers(0, 3)), int(rng.integers(0, 4)), int(rng.integers(0, 3)),
                      bool(rng.integers(0, 2)))
        if s not in found:
            found.append(s)
    return found


STRUCTURES = _structures()


def _stable_denominator(rng: np.random.Generator, n: int) -> np.ndarray:
    """``a_1 .. a_n`` of a polynomial whose roots (real or complex pairs) lie within 0.8."""
    roots: list[complex] = []
    while len(roots) < n:
        r, phase = rng.uniform(0.0, 0.8), rng.uniform(0.0, np.pi)
        if n - len(roots) >= 2 and rng.random() < 0.5:
            roots += [r * np.exp(1j * phase), r * np.exp(-1j * phase)]
        else:
            roots.append(r * rng.choice([-1.0, 1.0]))
    return np.real(np.poly(roots))[1:] if n else np.zeros(0)


def _random_case(structure: Structure, seed: int):
    """Parameters, a past of ``P`` samples (not at rest) and an input that does not start at
    rest, as extended arrays: the past at the head, sample ``k`` at index ``P + k``."""
    rng = np.random.default_rng(seed)
    s = structure
    values = {"alpha": rng.uniform(0.2, 1.0), "f0": rng.uniform(-0.2, 0.2),
              "f1": rng.uniform(0.2, 1.5), "g0": rng.uniform(-0.5, 0.5)}
    for prefix, n in (("a1", s.n1a), ("a2", s.n2a)):
        values.update({f"{prefix}{i + 1}": a
                       for i, a in enumerate(_stable_denominator(rng, n))})
    for prefix, n in (("b1", s.n1b), ("b2", s.n2b)):
        values.update({f"{prefix}{j}": rng.uniform(-0.6, 0.6) for j in range(1, n + 1)})
    theta = np.array([values[name] for name in s.names])
    P = s.history + 2
    t = np.arange(-P, N) / FS
    phases = rng.uniform(0, 2 * np.pi, 3)
    U = (0.3 + 0.5 * np.sin(2 * np.pi * 37.0 * t + phases[0])
         + 0.3 * np.sin(2 * np.pi * 211.0 * t + phases[1])
         + 0.1 * np.sin(2 * np.pi * 1130.0 * t + phases[2])
         + 0.01 * rng.standard_normal(P + N))
    past = {k: np.concatenate([rng.uniform(-0.3, 0.3, P), np.zeros(N)]) for k in ("w1", "w2", "y")}
    return theta, P, U, past


def _reference(structure: Structure, theta, P, U, past):
    """w1, w2, y of the one definition, :func:`hystid.kernels.simulate_into`."""
    W1, W2, Y = (past[k].copy() for k in ("w1", "w2", "y"))
    simulate_into(theta, structure.layout, U.copy(), W1, W2, Y, P)
    return W1[P:], W2[P:], Y[P:]


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    """Largest difference relative to the largest value of the reference ``b``."""
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def _ekf_run(structure: Structure, theta, P, U, past):
    """The EKF's prediction over the whole input: the transition with the state windows carried
    along, starting from the same past. Returns w1, w2, y and the (state, input window) before
    each step."""
    m1, m2, m3, mu = state_sizes(structure)
    o2, oy = m1, m1 + m2
    # windows most recent first: x[i] = w1(-1 - i), ...; ubuf[j] = u(k - j)
    x = np.concatenate([past["w1"][P - 1::-1][:m1], past["w2"][P - 1::-1][:m2],
                        past["y"][P - 1::-1][:m3], theta])
    ubuf = U[P - 1::-1][:mu].copy()
    n = len(x)
    xn, F = np.empty(n), np.empty((n, n))
    out = np.empty((3, N))
    before = []
    for k in range(N):
        ubuf[1:] = ubuf[:-1]
        ubuf[0] = U[P + k]
        before.append((x.copy(), ubuf.copy()))
        transition(x, ubuf, structure.layout, m1, m2, m3, xn, F)
        x = xn.copy()
        out[:, k] = x[0], x[o2], x[oy]
    return out, before


@pytest.mark.parametrize("structure", STRUCTURES, ids=str)
def test_ekf_prediction_is_the_step_of_kernels(structure):
    theta, P, U, past = _random_case(structure, seed=STRUCTURES.index(structure))
    ref = _reference(structure, theta, P, U, past)
    assert U[P] != 0 and np.all(past["w2"][:P] != 0)  # not starting at rest
    # the run stays in condition (8) and moves: a fair comparison, not of zeros or overflows
    dw1 = np.diff(np.concatenate([past["w1"][P - 1 : P], ref[0]]))
    assert np.max(theta[structure.names.index("alpha")] * np.abs(dw1)) < 2
    assert all(np.ptp(r) > 0.05 for r in ref)
    out, _ = _ekf_run(structure, theta, P, U, past)
    for got, want in zip(out, ref, strict=True):
        assert _rel(got, want) <= RTOL


@pytest.mark.parametrize("structure", STRUCTURES[::2], ids=str)
def test_ekf_jacobian_matches_central_differences_along_a_run(structure):
    theta, P, U, past = _random_case(structure, seed=100 + STRUCTURES.index(structure))
    m1, m2, m3, _ = state_sizes(structure)
    _, before = _ekf_run(structure, theta, P, U, past)
    n = len(before[0][0])
    xn, F = np.empty(n), np.empty((n, n))
    rng = np.random.default_rng(5)
    # points away from the Duhem block's kinks (dw1 = 0 and w1(k-1) = 0), which a difference
    # of step h would straddle
    ks = [k for k in rng.permutation(np.arange(1, N - 1))
          if min(abs(before[k + 1][0][0] - before[k][0][0]), abs(before[k][0][0])) > 1e-3][:5]
    assert len(ks) == 5
    h = 1e-6
    for k in ks:
        x, ubuf = before[k]
        transition(x, ubuf, structure.layout, m1, m2, m3, xn, F)
        J = np.empty((n, n))
        plus, minus, scratch = np.empty(n), np.empty(n), np.empty((n, n))
        for p in range(n):
            d = np.zeros(n)
            d[p] = h
            transition(x + d, ubuf, structure.layout, m1, m2, m3, plus, scratch)
            transition(x - d, ubuf, structure.layout, m1, m2, m3, minus, scratch)
            J[:, p] = (plus - minus) / (2 * h)
        assert np.max(np.abs(F - J)) <= 1e-6 * max(1.0, np.max(np.abs(F)))


def _augmented(structure: Structure, theta, P, U, past, phi):
    """w1, w2, y of the diagnosis' fused kernel from the same past (no creep, no mode yet)."""
    W1, W2, Y = (past[k].copy() for k in ("w1", "w2", "y"))
    V, YL = W2.copy(), Y.copy()
    UD, C, M = np.zeros(P + N), np.zeros(P + N), np.zeros(P + N)
    augmented_into(theta, structure.layout, phi, U.copy(), UD, W1, W2, V, C, YL, M, Y, P, 1 / FS)
    return W1[P:], W2[P:], Y[P:]


@pytest.mark.parametrize("structure", STRUCTURES, ids=str)
def test_augmented_kernel_with_every_effect_off_is_the_step_of_kernels(structure):
    theta, P, U, past = _random_case(structure, seed=200 + STRUCTURES.index(structure))
    ref = _reference(structure, theta, P, U, past)
    neutral = effect_vector(None)
    got = _augmented(structure, theta, P, U, past, neutral)
    for g, want in zip(got, ref, strict=True):
        assert _rel(g, want) <= RTOL
    # and the comparison sees an effect: a small asymmetry of the branches moves w2 and y
    eff = EFFECTS["asymmetry"]
    phi = neutral.copy()
    phi[eff.slots[eff.params.index("alpha")]] = 1e-3
    moved = _augmented(structure, theta, P, U, past, phi)
    assert _rel(moved[2], ref[2]) > 1e3 * RTOL


@pytest.mark.parametrize("structure", STRUCTURES[:3], ids=str)
def test_augmented_sandwich_without_effects_simulates_as_the_model(structure):
    theta, P, U, past = _random_case(structure, seed=3)
    model = DuhemSandwich(theta, structure, fs=FS, u_rest=0.2, offset=-0.1)
    x0 = InitialCondition(u=U[:P], w1=past["w1"][:P], w2=past["w2"][:P], y=past["y"][:P])
    u = U[P:] + model.u_rest
    want = model.simulate(u, x0, check=False)
    got = AugmentedSandwich(model).simulate(u, x0)
    for name in ("w1", "w2", "y"):
        assert _rel(getattr(got, name), getattr(want, name)) <= RTOL


# --------------------------------------------------------------------------- the guard
RICHER = {"directional": {"directional": True}, "cubic": {"f_order": 3},
          "slope": {"g_order": 1}}


@pytest.mark.parametrize("shape", RICHER)
def test_ekf_and_augmented_model_refuse_a_generalised_block(shape):
    richer = Structure(**RICHER[shape])
    assert len(richer.layout) > PLAIN_DUHEM_LAYOUT and not richer.is_plain
    with pytest.raises(ValueError, match=r"method='ekf'.*plain Duhem"):
        KalmanIdentifier(structure=richer)
    values = {**reference_model().params, **{n: 0.0 for n in richer.names[6:]}}
    model = DuhemSandwich(values, richer)
    with pytest.raises(ValueError, match=r"augmented sandwich.*plain Duhem"):
        AugmentedSandwich(model)
    with pytest.raises(ValueError, match=r"augmented sandwich.*plain Duhem"):
        augmented_output(model, effect_vector(None), np.zeros(10))
    with pytest.raises(ValueError, match=r"diagnose supports only the plain Duhem"):
        diagnose(reference_record(0.2), structure=richer, progress=False)
    with pytest.raises(ValueError, match=r"diagnose supports only the plain Duhem"):
        diagnose(reference_record(0.2), model=model, progress=False)


def test_check_plain_duhem_names_the_option_and_what_it_found():
    plain = Structure(2, 2, 3, 2, 3, 2, True).layout
    check_plain_duhem(plain, "an option")  # the plain sandwich passes (its shape entries zero)
    check_plain_duhem(plain[:PLAIN_DUHEM_LAYOUT], "an option")
    with pytest.raises(ValueError, match=r"^an option supports.*entries \[2, 1, 0\] after"):
        check_plain_duhem(np.r_[plain[:PLAIN_DUHEM_LAYOUT], 2, 1, 0], "an option")
    with pytest.raises(ValueError, match=r"only 6 entries"):
        check_plain_duhem(plain[:6], "an option")


@pytest.mark.parametrize("structure", STRUCTURES[:6], ids=str)
def test_one_sample_step_is_the_loop_bit_for_bit(structure):
    """The kernels' loop (:func:`hystid.kernels.advance`, :func:`~hystid.kernels.sens_rows`,
    which read theta and the layout once) and their one-sample forms (``step``,
    ``step_sens_row``, as the on-line recursions call them) give the same bits."""
    from hystid.kernels import sensitivities_into, step, step_sens_row

    theta, P, U, past = _random_case(structure, seed=7)
    loop = [past[k].copy() for k in ("w1", "w2", "y")]
    simulate_into(theta, structure.layout, U.copy(), *loop, P)
    one = [past[k].copy() for k in ("w1", "w2", "y")]
    for k in range(P, P + N):
        step(theta, structure.layout, U, *one, k)
    for a, b in zip(loop, one, strict=True):
        assert np.array_equal(a, b)
    npar = len(theta)
    sens_loop = [np.zeros((P + N, npar)) for _ in range(3)]
    sig = [past[k].copy() for k in ("w1", "w2", "y")]
    sensitivities_into(theta, structure.layout, U.copy(), *sig, *sens_loop, P)
    sens_one = [np.zeros((P + N, npar)) for _ in range(3)]
    sig1 = [past[k].copy() for k in ("w1", "w2", "y")]
    for k in range(P, P + N):
        step_sens_row(theta, structure.layout, U, *sig1, *sens_one, k, k)
    for a, b in zip(sens_loop + sig, sens_one + sig1, strict=True):
        assert np.array_equal(a, b)
    assert np.any(sens_one[2][P:] != 0.0)
