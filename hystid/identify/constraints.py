"""The admissible parameter set: stable, minimum-phase L1 and L2 (Assumption 1) and alpha > 0.

A monic polynomial ``1 + c_1 z^-1 + ... + c_n z^-n`` has all its roots strictly inside the unit
circle iff its reflection (Schur-Cohn) coefficients ``k_1..k_n`` all lie in (-1, 1). The
identifiers search in reflection coefficients, where the admissible set is a box.
"""

from __future__ import annotations

import numpy as np

from ..model import Structure
from ..poly import STABILITY_MARGIN, schur_stable

__all__ = [
    "K_MAX",
    "ALPHA_MIN",
    "Reflections",
    "is_admissible",
    "poly_to_reflection",
    "project_admissible",
    "reflection_to_poly",
    "polynomial_groups",
]

K_MAX = 1.0 - 1e-6
ALPHA_MIN = 1e-9


def reflection_to_poly(k: np.ndarray, jacobian: bool = True
                       ) -> tuple[np.ndarray, np.ndarray | None]:
    """Step-up recursion: coefficients ``c_1..c_n`` and their Jacobian ``dc/dk`` (n x n).

    Parameters
    ----------
    k : ndarray
        Reflection coefficients.
    jacobian : bool
        Whether to form ``dc/dk`` (None in its place otherwise; ``c`` is the same).

    Returns
    -------
    tuple of ndarray
        ``c`` and ``dc/dk``.
    """
    k = np.asarray(k, dtype=float)
    n = len(k)
    c = np.zeros(0)
    dc = np.zeros((0, n)) if jacobian else None
    for m in range(n):
        # c^(m+1)_i = c^(m)_i + k_m c^(m)_(m+1-i), i = 1..m;  c^(m+1)_(m+1) = k_m
        rev = c[::-1]
        new = np.append(c + k[m] * rev, k[m])
        if dc is not None:
            dnew = np.vstack([dc + k[m] * dc[::-1], np.zeros((1, n))])
            dnew[:m, m] += rev
            dnew[m, m] = 1.0
            dc = dnew
        c = new
    return c, dc


def poly_to_reflection(c: np.ndarray) -> np.ndarray:
    """Step-down recursion: reflection coefficients of ``1 + c_1 z^-1 + ...``.

    Returns values with ``|k| >= 1`` when the polynomial has roots on or outside the unit circle.

    Parameters
    ----------
    c : ndarray
        Coefficients ``c_1 .. c_n``.

    Returns
    -------
    ndarray
        Reflection coefficients ``k_1 .. k_n``.
    """
    c = np.asarray(c, dtype=float).copy()
    n = len(c)
    k = np.zeros(n)
    for m in range(n, 0, -1):
        km = c[m - 1]
        k[m - 1] = km
        if m > 1:
            denom = 1.0 - km * km
            if abs(denom) < 1e-300:
                k[: m - 1] = np.sign(km)
                break
            c = (c[: m - 1] - km * c[: m - 1][::-1]) / denom
    return k


class Reflections:
    """theta <-> z: the monic polynomial groups of theta replaced by their reflection coefficients.

    The search space of every output-error fit (the Duhem sandwich's in
    :mod:`hystid.identify.offline`, the PI sandwich's in :mod:`hystid.identify.pi_recursive`):
    each group's reflection coefficients are boxed in ``[-K_MAX, K_MAX]``, so every iterate is
    stable (and minimum phase for numerator groups); entries listed in ``positive`` are kept at
    or above :data:`ALPHA_MIN`.

    Parameters
    ----------
    groups : list of ndarray
        Indices into theta of each monic polynomial ``1 + c_1 z^-1 + ...`` (``c_1`` first).
    n : int
        Length of theta.
    positive : sequence of int
        Indices kept positive.
    """

    def __init__(self, groups: list[np.ndarray], n: int, positive: tuple[int, ...] = ()) -> None:
        self.groups = [np.asarray(g, dtype=int) for g in groups if len(g)]
        self.n = int(n)
        self.positive = tuple(positive)

    def to_z(self, theta: np.ndarray) -> np.ndarray:
        """Search coordinates of ``theta`` (reflection coefficients clipped into the box).

        Parameters
        ----------
        theta : ndarray
            Parameter vector.

        Returns
        -------
        ndarray
            ``z``, inside :meth:`bounds`.
        """
        z = np.array(theta, float)
        for g in self.groups:
            z[g] = np.clip(poly_to_reflection(theta[g]), -K_MAX, K_MAX)
        for i in self.positive:
            z[i] = max(z[i], ALPHA_MIN)
        return z

    def to_theta(self, z: np.ndarray, jacobian: bool = True
                 ) -> tuple[np.ndarray, np.ndarray | None]:
        """Parameters of ``z`` and the Jacobian ``d theta / d z``.

        Parameters
        ----------
        z : ndarray
            Search coordinates.
        jacobian : bool
            Whether to form the Jacobian (None in its place otherwise; ``theta`` is the same,
            for a caller that evaluates many ``z`` and needs the values alone).

        Returns
        -------
        theta : ndarray
            Parameter vector.
        dtheta : ndarray or None
            ``n x n`` Jacobian (block diagonal: identity outside the groups).
        """
        theta = np.array(z, float)
        if not jacobian:
            for g in self.groups:
                theta[g] = reflection_to_poly(z[g], jacobian=False)[0]
            return theta, None
        dtheta = np.eye(self.n)
        for g in self.groups:
            theta[g], dtheta[np.ix_(g, g)] = reflection_to_poly(z[g])
        return theta, dtheta

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of ``z``.

        Returns
        -------
        lo, hi : ndarray
            ``[-K_MAX, K_MAX]`` on the groups, ``ALPHA_MIN`` below the positive entries,
            unbounded elsewhere.
        """
        lo = np.full(self.n, -np.inf)
        hi = np.full(self.n, np.inf)
        for g in self.groups:
            lo[g], hi[g] = -K_MAX, K_MAX
        for i in self.positive:
            lo[i] = ALPHA_MIN
        return lo, hi


def polynomial_groups(structure: Structure) -> list[np.ndarray]:
    """Indices into theta of the monic polynomials a1, b1, a2, b2 (empty groups dropped).

    Parameters
    ----------
    structure : Structure
        The model structure.

    Returns
    -------
    list of ndarray
        One integer index array per polynomial.
    """
    names = structure.names
    groups = []
    for prefix, n in (("a1", structure.n1a), ("b1", structure.n1b),
                      ("a2", structure.n2a), ("b2", structure.n2b)):
        if n:
            groups.append(np.array([names.index(f"{prefix}{i}") for i in range(1, n + 1)]))
    return groups


def is_admissible(
    theta: np.ndarray, structure: Structure, margin: float = STABILITY_MARGIN
) -> bool:
    """True when alpha > 0 and every polynomial's reflection coefficients are below 1 - margin.

    Parameters
    ----------
    theta : ndarray
        Parameter vector in the order of ``structure.names``.
    structure : Structure
        The model structure.
    margin : float
        Distance kept from the unit circle.

    Returns
    -------
    bool
        Whether ``theta`` is admissible.
    """
    if not np.all(np.isfinite(theta)):
        return False
    if theta[structure.names.index("alpha")] <= 0:
        return False
    if "ad" in structure.names and not abs(theta[structure.names.index("ad")]) < 1.0:
        return False  # the generalised block's rates alpha (1 +- ad) stay positive
    return all(schur_stable(np.ascontiguousarray(theta[g]), 1.0 - margin)
               for g in polynomial_groups(structure))


def project_admissible(theta: np.ndarray, structure: Structure, kmax: float = 0.999) -> np.ndarray:
    """Nearest-in-reflection-coefficients admissible vector: clip each ``|k|`` to ``kmax``.

    Parameters
    ----------
    theta : ndarray
        Parameter vector in the order of ``structure.names``.
    structure : Structure
        The model structure.
    kmax : float
        Largest ``|k|`` kept.

    Returns
    -------
    ndarray
        The projected parameter vector.
    """
    theta = np.array(theta, dtype=float)
    ia = structure.names.index("alpha")
    theta[ia] = max(theta[ia], ALPHA_MIN)
    if "ad" in structure.names:
        i = structure.names.index("ad")
        theta[i] = np.clip(theta[i], -kmax, kmax)
    for g in polynomial_groups(structure):
        k = poly_to_reflection(theta[g])
        if np.any(~np.isfinite(k)) or np.any(np.abs(k) > kmax):
            theta[g] = reflection_to_poly(np.clip(np.nan_to_num(k), -kmax, kmax))[0]
    return theta
