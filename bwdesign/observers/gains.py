"""Observer gains: validation, the error matrix and pole matching to discrete gains."""

from __future__ import annotations

import functools
import math
from numbers import Real
from typing import Any

import numpy as np

from ..errors import GainError, InputError
from ..model.params import BoucWenParams
from ..model.plant import check_dt, discretize
from ..validate import GAIN

__all__ = [
    "disturbance_gains_from",
    "gains_for_observer",
    "hurwitz_violations",
    "GAIN_OBSERVERS",
    "check_gains",
    "error_matrix",
    "discrete_gains",
    "place_discrete",
    "delta_transition",
    "schur_margin",
    "check_disturbance_gains",
    "disturbance_discrete_gains",
]


C = np.array([1.0, 0.0, 0.0])


def as_gains(gains: Any, what: str = "gains") -> np.ndarray:
    """``gains`` as three finite floats inside :data:`bwdesign.validate.GAIN`, or ``GainError``."""
    try:
        g = np.asarray(gains)
    except (TypeError, ValueError):
        raise GainError(f"{what} must be three numbers (l1, l2, l3), got {gains!r}") from None
    bools = isinstance(gains, list | tuple) and any(isinstance(v, bool | np.bool_) for v in gains)
    if g.dtype.kind not in "fiu" or bools:  # strings, booleans, None
        raise GainError(f"{what} must be three numbers (l1, l2, l3), got {gains!r}")
    g = g.astype(float)
    if g.shape != (3,):
        raise GainError(f"{what} must be three numbers (l1, l2, l3), got shape {g.shape}")
    if not np.all(np.isfinite(g)):
        raise GainError(f"{what} must be finite, got {g.tolist()}")
    for v in np.asarray(gains, dtype=object).ravel():
        if not isinstance(v, Real) or isinstance(v, bool):
            raise GainError(f"{what} must be numbers, got {type(v).__name__} {v!r}")
    if not all(x in GAIN for x in g.tolist()):
        raise GainError(f"{what} {g.tolist()} are outside the supported range {GAIN.text()}")
    return g


def hurwitz_violations(params: BoucWenParams, gains: Any) -> list[str]:
    """The Hurwitz conditions (4) that the gains violate (empty when ``A0 - l C`` is Hurwitz).

    ``l1 + a2 > 0``, ``(l1 + a2)(l1 a2 + a1 + l2) + l3 a1 > 0`` and ``l3 a1 < 0``
    make ``A0 - l C`` Hurwitz (Routh-Hurwitz on its characteristic polynomial).
    Each violated one is a line naming the condition and its value.

    Raises
    ------
    GainError
        The gains are not three finite numbers in the supported range (a malformed
        input, as opposed to well-formed gains that are not stabilising).
    """
    l1, l2, l3 = as_gains(gains)
    a1, a2 = params.a1, params.a2
    c2 = (l1 + a2) * (l1 * a2 + a1 + l2) + l3 * a1
    failed = []
    if not l1 + a2 > 0:
        failed.append(f"l1 + a2 > 0 (it is {l1 + a2:.6g})")
    if not c2 > 0:
        failed.append(
            f"(l1 + a2)(l1 a2 + a1 + l2) + l3 a1 > 0 (it is {c2:.6g}; raise l1 or l2, "
            "or reduce |l3|)"
        )
    if not l3 * a1 < 0:
        failed.append("l3 a1 < 0 (l3 must be negative)")
    return failed


def check_gains(params: BoucWenParams, gains: Any) -> np.ndarray:
    """Validate continuous observer gains against the Hurwitz conditions (4).

    See :func:`hurwitz_violations` for the conditions.

    Returns
    -------
    ndarray, shape (3,)

    Raises
    ------
    GainError
        Wrong length, non-finite, or a violated condition (named in the message).
    """
    l1, l2, l3 = g = as_gains(gains)
    failed = hurwitz_violations(params, g)
    if failed:
        raise GainError(
            f"observer gains l = ({l1:g}, {l2:g}, {l3:g}) on {params.name or 'the plant'}: "
            f"A = A0 - l C is not Hurwitz; they violate {'; '.join(failed)}"
        )
    return g


def error_matrix(params: BoucWenParams, gains: Any) -> np.ndarray:
    """Continuous error matrix ``A = A0 - l C`` of paper eq. (5).

    ``A = [[-l1, 1, 0], [-(a1 + l2), -a2, -a1], [-l3, 0, 0]]``.
    """
    l1, l2, l3 = as_gains(gains)
    return np.array([[-l1, 1.0, 0.0], [-(params.a1 + l2), -params.a2, -params.a1], [-l3, 0.0, 0.0]])


def _expm1_complex(x: np.ndarray) -> np.ndarray:
    """``exp(x) - 1`` for complex ``x`` without cancellation near ``x = 0``."""
    x = np.asarray(x, dtype=complex)
    a, b = x.real, x.imag
    re = np.expm1(a) * np.cos(b) - 2.0 * np.sin(b / 2.0) ** 2
    return re + 1j * np.exp(a) * np.sin(b)


def delta_transition(params: BoucWenParams, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``F = expm(A0 dt)`` and its delta form ``(F - I)/dt``, both accurate to round-off.

    ``(F - I)/dt = A0 phi1(A0 dt)`` with ``phi1(X) = (expm(X) - I) X^-1``, taken
    from the exponential of the augmented matrix ``[[A0 dt, I], [0, 0]]`` in the
    coordinates ``(x1, x2/sqrt(a1), x3)``, so nothing cancels when ``|lambda| dt``
    is small (subtracting ``I`` from ``F`` would lose ``-log10(|lambda| dt)``
    digits).

    Returns
    -------
    F : ndarray, shape (3, 3)
        The ZOH transition with the x3 row ``[0, 0, 1]`` (as :func:`discretize`).
    Fd : ndarray, shape (3, 3)
        ``(F - I)/dt`` (1/s).
    """
    dt = check_dt(dt)
    F = np.array(discretize(params, dt).F)
    return F, _delta_form(params.a1, params.a2, dt).copy()


@functools.lru_cache(maxsize=256)
def _delta_form(a1: float, a2: float, dt: float) -> np.ndarray:
    from scipy.linalg import expm

    w0 = math.sqrt(a1)
    Az = np.array([[0.0, w0, 0.0], [-w0, -a2, -w0], [0.0, 0.0, 0.0]])
    M = np.zeros((6, 6))
    M[:3, :3] = Az * dt
    M[:3, 3:] = np.eye(3)
    phi1 = expm(M)[:3, 3:]
    Fdz = Az @ phi1
    s = np.array([1.0, 1.0 / w0, 1.0])  # z = S x
    Fd = Fdz * s[None, :] / s[:, None]
    Fd[2] = 0.0
    Fd.setflags(write=False)
    return Fd


def discrete_gains(params: BoucWenParams, gains: Any, dt: float) -> np.ndarray:
    """Discrete correction ``K`` whose error poles are ``exp(lambda_i dt)``.

    ``lambda_i`` are the eigenvalues of ``A0 - l C``. The poles are placed in
    the delta form ``((I - K C) F - I)/dt = (F - I)/dt - (K/dt) C F`` at
    ``(exp(lambda_i dt) - 1)/dt`` (both sides accurate to round-off, see
    :func:`delta_transition`), with Ackermann's formula in the coordinates
    ``(x1, x2/sqrt(a1), x3)`` and time in units of ``1/sqrt(a1)``. In that form
    the matrices are of order one for every ``|lambda| dt``; Ackermann's
    formula on ``F`` itself (which tends to ``I`` as ``dt -> 0``) cancels
    catastrophically when ``|lambda| dt`` is small. When no pole is near
    ``z = 1`` (every ``|z_i - 1| > 0.5``) the z form is used instead, which keeps
    poles close to ``z = 0`` that the delta form would round to ``-1/dt``.

    Parameters
    ----------
    params : BoucWenParams
    gains : array_like, shape (3,)
        Continuous gains (1/s, 1/s^2, 1/s).
    dt : float
        Sample time (s).

    Returns
    -------
    ndarray, shape (3,)
    """
    dt = check_dt(dt)
    w0 = math.sqrt(params.a1)
    T = np.array([1.0, w0, 1.0])
    A = error_matrix(params, gains)
    lam = np.linalg.eigvals(A * T[None, :] / T[:, None] / w0) * w0
    zm1 = _expm1_complex(lam * dt)
    if float(np.min(np.abs(zm1))) > Z_FORM_BELOW:
        # no pole near z = 1: F is far from I and the z form keeps the small |z_i|
        # (which the delta form would round to -1/dt)
        return _place_z(params, np.exp(lam * dt), dt)
    return _place_delta(params, zm1 / dt, dt)


#: Poles are placed in the z form when every ``|z_i - 1|`` exceeds this (else delta form).
Z_FORM_BELOW = 0.5


def _place_z(params: BoucWenParams, poles: np.ndarray, dt: float) -> np.ndarray:
    """Ackermann's formula for ``(F, C F)`` in the coordinates ``(x1, x2/sqrt(a1), x3)``."""
    F = discretize(params, dt).F
    w0 = math.sqrt(params.a1)
    s = np.array([1.0, 1.0 / w0, 1.0])  # z = S x
    Fz = s[:, None] * F / s[None, :]
    Hz = (C @ F) / s
    O = np.vstack([Hz, Hz @ Fz, Hz @ Fz @ Fz])
    coeffs = np.real(np.poly(poles))
    pF = coeffs[0] * Fz @ Fz @ Fz + coeffs[1] * Fz @ Fz + coeffs[2] * Fz + coeffs[3] * np.eye(3)
    try:
        Kz = pF @ np.linalg.solve(O, np.array([0.0, 0.0, 1.0]))
    except np.linalg.LinAlgError:
        raise GainError(
            f"the sampled model is not observable at dt = {dt:g} s; choose another dt"
        ) from None
    return Kz / s


def place_discrete(params: BoucWenParams, poles: np.ndarray, dt: float) -> np.ndarray:
    """``K`` with eig((I - K C) F) = ``poles`` (a self-conjugate set of three)."""
    dt = check_dt(dt)
    z = np.asarray(poles, dtype=complex).ravel()
    return _place_delta(params, (z - 1.0) / dt, dt)


def _place_delta(params: BoucWenParams, deltas: np.ndarray, dt: float) -> np.ndarray:
    """``K`` with eig(((I - K C) F - I)/dt) = ``deltas`` (1/s), by Ackermann in delta form."""
    F, Fd = delta_transition(params, dt)
    w0 = math.sqrt(params.a1)
    s = np.array([1.0, 1.0 / w0, 1.0])  # z = S x
    Az = Fd * s[:, None] / s[None, :] / w0  # (F - I)/dt in z, time in 1/w0
    Hz = (C @ F) / s
    O = np.vstack([Hz, Hz @ Az, Hz @ Az @ Az])
    coeffs = np.real(np.poly(np.asarray(deltas, dtype=complex) / w0))
    pA = coeffs[0] * Az @ Az @ Az + coeffs[1] * Az @ Az + coeffs[2] * Az + coeffs[3] * np.eye(3)
    try:
        g = pA @ np.linalg.solve(O, np.array([0.0, 0.0, 1.0]))
    except np.linalg.LinAlgError:
        raise GainError(
            f"the sampled model is not observable at dt = {dt:g} s; choose another dt"
        ) from None
    return dt * w0 * g / s


def schur_margin(params: BoucWenParams, K: Any, dt: float) -> tuple[float, np.ndarray]:
    """Stability of the nominal discrete error dynamics ``(I - K C) F``.

    Computed in delta form: with ``delta_i`` the eigenvalues of
    ``(F - I)/dt - (K/dt) C F``, the poles are ``z_i = 1 + dt delta_i`` and
    ``|z_i|^2 - 1 = dt (2 Re delta_i + dt |delta_i|^2)``, evaluated without
    cancelling against 1.

    Returns
    -------
    margin : float
        ``max_i (|z_i|^2 - 1)``; the dynamics are Schur stable when it is < 0.
    z : ndarray, shape (3,)
        The poles ``z_i``.
    """
    dt = check_dt(dt)
    F, Fd = delta_transition(params, dt)
    K = as_gains(K, "discrete gains K")
    w0 = math.sqrt(params.a1)
    T = np.array([1.0, w0, 1.0])
    Ad = Fd - np.outer(K / dt, F[0])
    d = np.linalg.eigvals(Ad * T[None, :] / T[:, None] / w0) * w0
    margin = float(np.max(dt * (2.0 * d.real + dt * np.abs(d) ** 2)))
    return margin, 1.0 + dt * d


def _as_four(gains: Any, what: str) -> np.ndarray:
    names = "(l1, l2, l3, l4)" if what == "gains" else "(k1, k2, k3, k4)"
    try:
        g = np.asarray(gains)
    except (TypeError, ValueError):
        raise GainError(f"{what} must be four numbers {names}, got {gains!r}") from None
    bools = isinstance(gains, list | tuple) and any(isinstance(v, bool | np.bool_) for v in gains)
    if g.dtype.kind not in "fiu" or bools or g.shape != (4,):
        raise GainError(f"{what} must be four numbers {names}, got {gains!r}")
    g = g.astype(float)
    if not np.all(np.isfinite(g)):
        raise GainError(f"{what} must be finite, got {g.tolist()}")
    if g[3] == 0.0:
        raise GainError(
            f"{what} {g.tolist()}: the disturbance gain (4th) is 0, so d never moves; "
            "that is the plain hysteresis observer (HysteresisObserver)"
        )
    return g


def disturbance_gains_from(gains: Any) -> tuple[float, float, float, float]:
    """The disturbance observer's gains ``(l1, l2, 0, l3)`` from a 3-state design ``(l1, l2, l3)``.

    Its observable part ``(x1, x2, x3 + d)`` then has the poles of the 3-state
    design, the whole correction of the lumped state goes to ``d``, and the
    hysteresis copy runs on the model alone (``l3 = 0``). The same map takes
    discrete 3-state gains ``(k1, k2, k3)`` to the PHDO's ``(k1, k2, 0, k3)``.
    """
    l1, l2, l3 = (float(g) for g in as_gains(gains))
    return (l1, l2, 0.0, l3)


#: The sampled observers that run a 3-state design's gains (the PHDO through
#: :func:`disturbance_gains_from`).
GAIN_OBSERVERS = ("phso", "eso", "phdo")


def gains_for_observer(observer: str, gains: Any) -> tuple[float, ...]:
    """The gains ``observer`` runs for the 3-state design ``gains``: the package's one map.

    ``"phso"`` and ``"eso"`` run ``(l1, l2, l3)`` as given; ``"phdo"`` (the
    disturbance observer) runs ``(l1, l2, 0, l3)`` (:func:`disturbance_gains_from`).
    Used wherever 3-state gains meet the PHDO: ``export-c``,
    :func:`bwdesign.testing.assert_c_matches_python`, sweeps, the digital tuning
    and the robust design.

    Raises
    ------
    InputError
        ``observer`` is not one of ``"phso"``, ``"eso"``, ``"phdo"``.
    GainError
        ``gains`` are not three finite numbers.
    """
    if observer not in GAIN_OBSERVERS:
        raise InputError(
            f"observer must be one of {', '.join(map(repr, GAIN_OBSERVERS))}, got {observer!r}"
        )
    if observer == "phdo":
        return disturbance_gains_from(gains)
    return tuple(float(g) for g in as_gains(gains))


def check_disturbance_gains(params: BoucWenParams, gains: Any) -> np.ndarray:
    """Validate the continuous gains ``(l1, l2, l3, l4)`` of the disturbance observer.

    The linear part sees only the lumped ``w = x3 + d``, whose injection gain is
    ``l3 + l4``; ``(l1, l2, l3 + l4)`` must satisfy the Hurwitz conditions (4)
    (:func:`check_gains`). ``l3`` (any sign, 0 allowed) splits the correction
    between the hysteresis copy and ``d``; ``l4`` must be nonzero.

    Returns
    -------
    ndarray, shape (4,)
        (l1 1/s, l2 1/s^2, l3 1/s, l4 1/s).

    Raises
    ------
    GainError
    """
    g = _as_four(gains, "gains")
    check_gains(params, (g[0], g[1], g[2] + g[3]))
    return g


def disturbance_discrete_gains(params: BoucWenParams, gains: Any, dt: float) -> np.ndarray:
    """Discrete ``K = (k1, k2, k3, k4)`` of the disturbance observer, by pole matching.

    The observable part in the coordinates ``(x1, x2, w = x3 + d)`` is the
    3-state model with the lumped gain ``l3 + l4``: its correction
    ``(k1, k2, kw)`` is :func:`discrete_gains` of ``(l1, l2, l3 + l4)`` (poles
    ``exp(lambda_i dt)``), and ``kw`` is split as the continuous gains are:
    ``k3 = kw l3 / (l3 + l4)``, ``k4 = kw l4 / (l3 + l4)``.

    Returns
    -------
    ndarray, shape (4,)
    """
    l1, l2, l3, l4 = check_disturbance_gains(params, gains)
    lw = l3 + l4
    k1, k2, kw = discrete_gains(params, (l1, l2, lw), dt)
    return np.array([k1, k2, kw * (l3 / lw), kw * (l4 / lw)])


def check_disturbance_discrete(K: Any) -> np.ndarray:
    """Validate discrete gains ``(k1, k2, k3, k4)``; ``(k1, k2, k3 + k4)`` must be in range."""
    g = _as_four(K, "discrete gains K")
    as_gains((g[0], g[1], g[2] + g[3]), "discrete gains (k1, k2, k3 + k4)")
    return g
