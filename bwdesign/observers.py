"""Hysteresis observer (PHSO, paper eq. 3) and extended state observer (ESO, eq. 21).

Both come in two forms:

- **Discrete, filterpy-style** classes for the sample rate a stage runs at:
  ``predict(u_k)`` carries the estimate from ``t_k`` to ``t_{k+1}`` with
  ``u_k`` held, propagating the model copy *exactly* (the closed-form
  hysteresis jump ``u_{k-1} -> u_k`` for the PHSO, then the zero-order-hold
  linear part); ``update(z)`` corrects with ``z = y(t_{k+1})``::

      x_prior = F [x1, x2, H(x3, u_{k-1}, u_k)] + g u_k        (PHSO)
      x_prior = F x + g u_k                                     (ESO: x3 held)
      x_post  = x_prior + K (z - x_prior[0])

- **Continuous-time** right-hand sides (:func:`phso_rhs`, :func:`eso_rhs`) for
  analysis and for the paper's continuous simulations, and the same observers
  as python-control ``NonlinearIOSystem`` objects (:func:`observer_iosystem`,
  ``as_iosystem()``) for ``control.interconnect`` and
  ``control.input_output_response``.

Continuous gains ``l`` map to the discrete correction ``K`` by pole matching:
the nominal discrete error matrix ``(I - K C) F`` gets the eigenvalues
``exp(lambda_i dt)`` of the continuous error matrix ``A0 - l C``
(:func:`discrete_gains`). As ``dt -> 0``, ``K ~ l dt`` and the discrete
observer converges to the continuous one.

Error dynamics of the discrete PHSO (used by the ``sampled`` certificate)::

    eps_post[k+1] = (I - K C) F diag(1, 1, rho_k) eps_post[k]

with ``rho_k`` the slope of the hysteresis jump map between the true and the
estimated state.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .errors import GainError, InputError
from .params import BoucWenParams, require_bounded
from .plant import ZOHModel, _check_dt, discretize, hysteresis_increment, phi

__all__ = [
    "HysteresisObserver",
    "ExtendedStateObserver",
    "check_gains",
    "error_matrix",
    "discrete_gains",
    "phso_step",
    "eso_step",
    "phso_rhs",
    "eso_rhs",
    "observer_iosystem",
]

C = np.array([1.0, 0.0, 0.0])


def _as_gains(gains: Any, what: str = "gains") -> np.ndarray:
    try:
        g = np.asarray(gains, dtype=float)
    except (TypeError, ValueError):
        raise GainError(f"{what} must be three numbers (l1, l2, l3), got {gains!r}") from None
    if g.shape != (3,):
        raise GainError(f"{what} must be three numbers (l1, l2, l3), got shape {g.shape}")
    if not np.all(np.isfinite(g)):
        raise GainError(f"{what} must be finite, got {g.tolist()}")
    return g


def check_gains(params: BoucWenParams, gains: Any) -> np.ndarray:
    """Validate continuous observer gains against the Hurwitz conditions (4).

    ``l1 + a2 > 0``, ``(l1 + a2)(l1 a2 + a1 + l2) + l3 a1 > 0`` and ``l3 a1 < 0``
    make ``A0 - l C`` Hurwitz (Routh-Hurwitz on its characteristic polynomial).

    Returns
    -------
    ndarray, shape (3,)

    Raises
    ------
    GainError
        Wrong length, non-finite, or a violated condition (named in the message).
    """
    l1, l2, l3 = g = _as_gains(gains)
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
    l1, l2, l3 = _as_gains(gains)
    return np.array([[-l1, 1.0, 0.0], [-(params.a1 + l2), -params.a2, -params.a1], [-l3, 0.0, 0.0]])


def discrete_gains(params: BoucWenParams, gains: Any, dt: float) -> np.ndarray:
    """Discrete correction ``K`` whose error poles are ``exp(lambda_i dt)``.

    ``lambda_i`` are the eigenvalues of ``A0 - l C``. Ackermann's formula for
    the pair ``(F, C F)`` places the eigenvalues of ``(I - K C) F``; it is
    evaluated with ``x2`` scaled by ``sqrt(a1)`` so the 3x3 problem is well
    conditioned for a1 from 1e3 to 1e9, and it handles repeated poles.

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
    lam = np.linalg.eigvals(error_matrix(params, gains))
    return place_discrete(params, np.exp(lam * _check_dt(dt)), dt)


def place_discrete(params: BoucWenParams, poles: np.ndarray, dt: float) -> np.ndarray:
    """``K`` with eig((I - K C) F) = ``poles`` (a self-conjugate set of three)."""
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


def phso_step(
    params: BoucWenParams,
    zoh: ZOHModel,
    K: np.ndarray,
    x: np.ndarray,
    u_prev: float,
    u: float,
    z: float | None,
) -> tuple[np.ndarray, np.ndarray]:
    """One predict/update of the PHSO as a plain function.

    Returns
    -------
    (x_prior, x_post) : ndarrays, shape (3,)
    """
    h = hysteresis_increment(params, float(x[2]), float(u_prev), float(u))
    prior = zoh.F @ np.array([x[0], x[1], h]) + zoh.g * u
    post = prior if z is None else prior + K * (z - prior[0])
    return prior, post


def eso_step(
    params: BoucWenParams,
    zoh: ZOHModel,
    K: np.ndarray,
    x: np.ndarray,
    u_prev: float,
    u: float,
    z: float | None,
) -> tuple[np.ndarray, np.ndarray]:
    """One predict/update of the ESO as a plain function (x3 held in the predict)."""
    prior = zoh.F @ np.asarray(x, dtype=float) + zoh.g * u
    post = prior if z is None else prior + K * (z - prior[0])
    return prior, post


def phso_rhs(
    params: BoucWenParams, gains: Any, xhat: np.ndarray, u: float, udot: float, y: float
) -> np.ndarray:
    """Continuous PHSO, paper eq. (3): the model copy plus injection on ``y - x1hat``.

    Parameters
    ----------
    params : BoucWenParams
    gains : sequence of float, length 3
        Continuous gains (l1 in 1/s, l2 in 1/s^2, l3 in 1/s); not validated here
        (use :func:`check_gains`).
    xhat : array_like, shape (3,)
        Estimate (x1 displacement, x2 velocity, x3 hysteresis; length unit, length unit/s,
        length unit).
    u : float
        Input (V).
    udot : float
        Input rate u' (V/s); the PHSO needs it for the hysteresis copy phi(u', x3hat).
    y : float
        Measured displacement (length unit).

    Returns
    -------
    ndarray, shape (3,)
        d xhat / dt.
    """
    l1, l2, l3 = gains
    x1, x2, x3 = xhat
    r = y - x1
    return np.array(
        [
            x2 + l1 * r,
            -params.a1 * (x1 + x3) - params.a2 * x2 + params.a3 * u + l2 * r,
            phi(params, udot, x3) + l3 * r,
        ]
    )


def eso_rhs(
    params: BoucWenParams, gains: Any, xhat: np.ndarray, u: float, udot: float, y: float
) -> np.ndarray:
    """Continuous ESO, paper eq. (21): ``x3hat' = l3 (y - x1hat)`` (no hysteresis model).

    Same arguments as :func:`phso_rhs`; ``udot`` is accepted for a common signature
    and ignored.
    """
    l1, l2, l3 = gains
    x1, x2, x3 = xhat
    r = y - x1
    return np.array(
        [
            x2 + l1 * r,
            -params.a1 * (x1 + x3) - params.a2 * x2 + params.a3 * u + l2 * r,
            l3 * r,
        ]
    )


_RHS = {"phso": phso_rhs, "eso": eso_rhs}


def observer_iosystem(
    params: BoucWenParams,
    gains: Any,
    *,
    kind: str = "phso",
    name: str | None = None,
    allow_unbounded: bool = False,
):
    """The continuous observer as a python-control ``NonlinearIOSystem``.

    Inputs ``u`` (V), ``udot`` (V/s) and ``y`` (measured displacement, length
    unit); states and outputs ``xhat[0]``, ``xhat[1]``, ``xhat[2]`` (the
    estimate). Signal names follow python-control's vector convention, so
    ``control.interconnect`` connects ``y`` to a plant output named ``y`` and
    ``u``/``udot`` to external inputs of the same names, and ``'xhat'`` selects
    all three outputs.

    Parameters
    ----------
    params : BoucWenParams
    gains : array_like, shape (3,)
        Continuous gains (l1 in 1/s, l2 in 1/s^2, l3 in 1/s), checked against the
        Hurwitz conditions (4).
    kind : {"phso", "eso"}
        Hysteresis observer (eq. 3) or extended state observer (eq. 21).
    name : str, optional
        System name (default: ``kind``).
    allow_unbounded : bool
        Accept parameters outside the bounded class.

    Returns
    -------
    control.NonlinearIOSystem

    Raises
    ------
    GainError
        Gains of the wrong length, non-finite, or violating conditions (4).
    ValueError
        Unknown ``kind``.

    Examples
    --------
    >>> import numpy as np, control
    >>> from bwdesign import preset
    >>> from bwdesign.plant import rhs
    >>> p = preset("paper_experiment")
    >>> plant = control.nlsys(lambda t, x, u, _: rhs(p, x, u[0], u[1]),
    ...                       lambda t, x, u, _: x[:1], inputs=["u", "udot"],
    ...                       states=3, outputs=["y"], name="plant")
    >>> obs = observer_iosystem(p, (8.0, 64.0, -512.0))
    >>> loop = control.interconnect([plant, obs], inplist=["u", "udot"],
    ...                             outlist=["y", "xhat"])
    >>> t = np.linspace(0.0, 0.05, 51)
    >>> resp = control.input_output_response(loop, t, [np.full_like(t, 10.0), 0 * t],
    ...                                      initial_state=[1.0, 0, 0, 0, 0, 0])
    >>> resp.outputs.shape
    (4, 51)
    """
    import control  # heavy import, only needed here

    if kind not in _RHS:
        raise InputError(f"kind must be 'phso' or 'eso', got {kind!r}")
    require_bounded(params, allow_unbounded)
    g = tuple(check_gains(params, gains).tolist())
    f = _RHS[kind]

    def updfcn(t, x, u, _params):
        return f(params, g, x, u[0], u[1], u[2])

    def outfcn(t, x, u, _params):
        return x

    xhat = ["xhat[0]", "xhat[1]", "xhat[2]"]
    return control.nlsys(
        updfcn,
        outfcn,
        inputs=["u", "udot", "y"],
        states=list(xhat),
        outputs=list(xhat),
        name=name or kind,
    )


def _finite_scalar(v: Any, name: str) -> float:
    """``v`` as a finite float; a size-1 array (filterpy's ``z`` of shape (1,)) is accepted."""
    if isinstance(v, float | int) and not isinstance(v, bool):
        f = float(v)
    else:
        try:
            a = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            raise InputError(f"{name} must be a number, got {v!r}") from None
        if a.size != 1:
            raise InputError(f"{name} must be a single number, got shape {a.shape}")
        f = float(a.reshape(()))
    if not math.isfinite(f):
        raise InputError(f"{name} must be finite, got {f}")
    return f


def _measurements(zs: Any, n: int) -> list[float | None]:
    """Validate a record of measurements (``None`` = missing) as python floats."""
    if isinstance(zs, np.ndarray) and zs.dtype.kind in "fiu":
        z = zs.reshape(-1) if zs.ndim == 2 and zs.shape[1:] == (1,) else zs
        if z.ndim != 1 or z.size != n:
            raise InputError(
                f"zs must be 1-D (or (N, 1)) with one measurement per input, got shape "
                f"{zs.shape} for {n} inputs"
            )
        if not np.all(np.isfinite(z)):
            k = int(np.flatnonzero(~np.isfinite(z))[0])
            raise InputError(
                f"z must be finite, got zs[{k}] = {z[k]} (use None for a missing sample)"
            )
        return z.astype(float).tolist()
    if len(zs) != n:
        raise InputError(f"zs and us must have the same length, got {len(zs)} and {n}")
    return [None if z is None else _finite_scalar(z, "z") for z in zs]


def _inputs(us: Any) -> list[float]:
    u = np.asarray(us, dtype=float)
    if u.ndim != 1:
        raise InputError(f"us must be a 1-D sequence of held inputs (V), got shape {u.shape}")
    if not np.all(np.isfinite(u)):
        k = int(np.flatnonzero(~np.isfinite(u))[0])
        raise InputError(f"u must be finite, got us[{k}] = {u[k]}")
    return u.tolist()


class _SampledObserver:
    """Shared machinery of the discrete observers (filterpy-style interface).

    The step is computed on python floats with the scalar entries of the ZOH
    matrices (one sample costs a few microseconds); :func:`phso_step` and
    :func:`eso_step` are independent array twins of it, checked against it in
    the tests.

    Attributes
    ----------
    x : ndarray, shape (3,)
        Current estimate (x1 displacement, x2 velocity, x3 hysteresis).
    x_prior, x_post : ndarray, shape (3,)
        Estimate after the last ``predict`` and after the last ``update``.
    K : ndarray, shape (3,)
        Discrete correction gains.
    gains : ndarray, shape (3,) or None
        Continuous gains the observer was built from (None if built from ``K``).
    y : float
        Last innovation ``z - x_prior[0]`` (0 for a skipped sample).
    z : float or None
        Last measurement.
    u_prev : float
        Input held over the previous sample (V).
    """

    _hysteresis = True
    kind = ""

    def __init__(
        self,
        params: BoucWenParams,
        gains: Any = None,
        dt: float = 2e-4,
        *,
        discrete: Any = None,
        x0: Any = None,
        u_prev: float = 0.0,
        allow_unbounded: bool = False,
    ) -> None:
        require_bounded(params, allow_unbounded)
        self.params = params
        self.dt = _check_dt(dt)
        self._zoh = discretize(params, self.dt)
        F, g = self._zoh.F, self._zoh.g
        # the two non-trivial rows of F and g (row 3 is x3+ = h, g3 = 0)
        self._coef = (*F[0].tolist(), *F[1].tolist(), float(g[0]), float(g[1]))
        if (gains is None) == (discrete is None):
            raise GainError(
                f"{type(self).__name__}: give either continuous gains (l1, l2, l3) or "
                "discrete=K, exactly one of them"
            )
        if discrete is None:
            self.gains = check_gains(params, gains)
            self.K = discrete_gains(params, self.gains, self.dt)
        else:
            self.gains = None
            self.K = _as_gains(discrete, "discrete gains K")
            rho = np.abs(np.linalg.eigvals(self._zoh.F - np.outer(self.K, C @ self._zoh.F)))
            if rho.max() >= 1.0:
                raise GainError(
                    f"discrete gains K = {self.K.tolist()} leave the nominal error dynamics "
                    f"unstable (spectral radius {rho.max():.6g} >= 1)"
                )
        self.reset(x0, u_prev=u_prev)

    def reset(self, x0: Any = None, *, u_prev: float = 0.0) -> None:
        """Restart from ``x0`` (default zeros) with ``u_prev`` (V) held before the first sample."""
        x = np.zeros(3) if x0 is None else np.array(x0, dtype=float)
        if x.shape != (3,) or not np.all(np.isfinite(x)):
            raise InputError(f"x0 must be a finite vector of shape (3,), got {x0!r}")
        self.x = x
        self.x_prior = x.copy()
        self.x_post = x.copy()
        self.u_prev = _finite_scalar(u_prev, "u_prev")
        self.y = 0.0
        self.z: float | None = None

    def predict(self, u: float) -> None:
        """Carry the estimate from ``t_k`` to ``t_{k+1}`` with ``u`` (V) held.

        For the PHSO the hysteresis copy first follows the jump ``u_prev -> u``
        in closed form; then the linear part is propagated exactly (ZOH).
        """
        u = _finite_scalar(u, "u")
        x1, x2, x3 = np.asarray(self.x, dtype=float).tolist()
        if self._hysteresis:
            x3 = hysteresis_increment(self.params, x3, self.u_prev, u)
        f11, f12, f13, f21, f22, f23, g1, g2 = self._coef
        prior = (
            f11 * x1 + f12 * x2 + f13 * x3 + g1 * u,
            f21 * x1 + f22 * x2 + f23 * x3 + g2 * u,
            x3,
        )
        self.x = np.array(prior)
        self.x_prior = np.array(prior)
        self.u_prev = u

    def update(self, z: float | None) -> None:
        """Correct with the measured displacement ``z = y(t_{k+1})``; ``None`` skips.

        Parameters
        ----------
        z : float, array of size 1, or None
            Measured displacement (length unit).
        """
        if z is None:
            self.z = None
            self.y = 0.0
            self.x_post = np.array(self.x, dtype=float)
            return
        z = _finite_scalar(z, "z")
        x1, x2, x3 = np.asarray(self.x, dtype=float).tolist()
        k1, k2, k3 = self.K.tolist()
        r = z - x1
        post = (x1 + k1 * r, x2 + k2 * r, x3 + k3 * r)
        self.z = z
        self.y = r
        self.x = np.array(post)
        self.x_post = np.array(post)

    def batch_filter(self, zs: Any, us: Any) -> np.ndarray:
        """Run ``predict(us[k])``, ``update(zs[k])`` over a record.

        Gives the same numbers as the loop (the same float operations in the
        same order) without its per-call overhead.

        Parameters
        ----------
        zs : sequence of float or None, length N
            ``zs[k] = y(t_{k+1})`` (length unit); ``None`` marks a missing sample.
        us : array_like, shape (N,)
            Held inputs (V).

        Returns
        -------
        ndarray, shape (N, 3)
            The posterior estimates at ``t_1 .. t_N``.
        """
        ul = _inputs(us)
        zl = _measurements(zs, len(ul))
        if not ul:
            return np.empty((0, 3))
        f11, f12, f13, f21, f22, f23, g1, g2 = self._coef
        k1, k2, k3 = self.K.tolist()
        x1, x2, x3 = np.asarray(self.x, dtype=float).tolist()
        up = self.u_prev
        params, hyst = self.params, self._hysteresis
        out = []
        append = out.append
        for uk, zk in zip(ul, zl, strict=True):
            if hyst:
                x3 = hysteresis_increment(params, x3, up, uk)
            x1, x2 = (
                f11 * x1 + f12 * x2 + f13 * x3 + g1 * uk,
                f21 * x1 + f22 * x2 + f23 * x3 + g2 * uk,
            )
            prior = (x1, x2, x3)
            if zk is not None:
                r = zk - x1
                x1, x2, x3 = x1 + k1 * r, x2 + k2 * r, x3 + k3 * r
            append((x1, x2, x3))
            up = uk
        res = np.array(out)
        self.x_prior = np.array(prior)
        self.y = 0.0 if zl[-1] is None else zl[-1] - prior[0]
        self.x, self.x_post, self.u_prev, self.z = res[-1].copy(), res[-1].copy(), up, zl[-1]
        return res

    def as_iosystem(self, name: str | None = None):
        """The continuous form of this observer as a python-control ``NonlinearIOSystem``.

        See :func:`observer_iosystem` (inputs ``u``, ``udot``, ``y``; states and
        outputs ``xhat[0..2]``).

        Raises
        ------
        GainError
            The observer was built from discrete gains ``K``, which do not
            define a continuous observer.
        """
        if self.gains is None:
            raise GainError(
                f"{type(self).__name__} was built from discrete gains K; the continuous "
                "form needs continuous gains (l1, l2, l3): build it with gains=..."
            )
        return observer_iosystem(
            self.params, self.gains, kind=self.kind, name=name, allow_unbounded=True
        )

    def __repr__(self) -> str:
        g = (
            f"gains={self.gains.tolist()}"
            if self.gains is not None
            else f"discrete={self.K.tolist()}"
        )
        return (
            f"{type(self).__name__}(plant={self.params.name or 'unnamed'!r}, {g}, "
            f"dt={self.dt:g}, x={np.array2string(np.asarray(self.x), precision=6)})"
        )


class HysteresisObserver(_SampledObserver):
    """The paper's hysteresis observer (PHSO, eq. 3), sampled exactly.

    Parameters
    ----------
    params : BoucWenParams
    gains : array_like, shape (3,), optional
        Continuous gains (l1 in 1/s, l2 in 1/s^2, l3 in 1/s) satisfying the
        Hurwitz conditions (4); mapped to ``K`` by pole matching.
    dt : float
        Sample time (s).
    discrete : array_like, shape (3,), optional
        Discrete correction gains ``K`` instead of ``gains``.
    x0 : array_like, shape (3,), optional
        Initial estimate (default zeros).
    u_prev : float
        Input held before the first sample (V).
    allow_unbounded : bool
        Accept parameters outside the bounded class.

    Examples
    --------
    >>> from bwdesign import preset
    >>> obs = HysteresisObserver(preset("paper_experiment"), (8.0, 64.0, -512.0), 2e-4)
    >>> obs.predict(1.0); obs.update(0.0)
    >>> obs.x.shape
    (3,)
    """

    _hysteresis = True
    kind = "phso"


class ExtendedStateObserver(_SampledObserver):
    """Extended state observer (ESO, eq. 21): x3 treated as an unknown constant.

    Same constructor and interface as :class:`HysteresisObserver`; its predict
    holds x3hat instead of following the hysteresis model.
    """

    _hysteresis = False
    kind = "eso"
