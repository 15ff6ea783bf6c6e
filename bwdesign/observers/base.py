"""The base class of the sampled, filterpy-style observers."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import GainError, InputError
from ..model.params import BoucWenParams, require_bounded
from ..model.plant import check_dt, discretize, hysteresis_increment
from ..validate import real
from .dynamics import observer_iosystem
from .gains import C, as_gains, check_gains, discrete_gains, schur_margin


def finite_scalar(v: Any, name: str) -> float:
    """``v`` as a finite float (:func:`bwdesign.validate.real`).

    Accepted: any ``numbers.Real`` (python and numpy integers and floats) and a
    numeric array of size 1 (filterpy's ``z`` of shape (1,)). Refused with
    :class:`InputError`: ``None``, booleans, strings and anything else, so that
    ``predict(None)``, ``update(True)`` or ``predict("1.0")`` never run.
    """
    if isinstance(v, bool | np.bool_):
        raise InputError(f"{name} must be a number, got the boolean {v!r}")
    if isinstance(v, np.ndarray | list | tuple):
        a = np.asarray(v)
        if a.dtype.kind not in "fiu":
            raise InputError(f"{name} must be a number, got {type(v).__name__} {v!r}")
        if a.size != 1:
            raise InputError(f"{name} must be a single number, got shape {a.shape}")
        v = a.reshape(()).item()
    elif isinstance(v, np.generic):
        v = v.item()  # a python number, so that messages print it as python does
    return real(v, name)


_WORDS = {3: "three", 4: "four"}


def state_vector(value: Any, name: str = "x", n: int = 3) -> np.ndarray:
    """A state as a new float array of shape (n,); (n,) and filterpy's (n, 1) are accepted."""
    a = np.asarray(value)
    if a.dtype.kind not in "fiu" or a.shape not in ((n,), (n, 1)):
        raise InputError(
            f"{name} must be {_WORDS.get(n, n)} finite numbers, shape ({n},) or ({n}, 1), got "
            f"{type(value).__name__} {value!r}"
        )
    x = a.astype(float).reshape(n)
    if not np.all(np.isfinite(x)):
        raise InputError(f"{name} must be finite, got {x.tolist()}")
    return x


def require_finite_state(x: Any, owner: str) -> None:
    """Refuse to step from a non-finite estimate (e.g. ``obs.x[0] = nan`` in place)."""
    if not np.all(np.isfinite(x)):
        raise InputError(
            f"{owner}: the estimate x = {np.asarray(x).tolist()} is not finite; reset() it"
        )


def check_params(params: Any, owner: str) -> None:
    """Refuse anything but a :class:`BoucWenParams` (``owner`` names the caller)."""
    if not isinstance(params, BoucWenParams):
        hint = " (a preset name? use bwdesign.preset(name))" if isinstance(params, str) else ""
        raise InputError(
            f"{owner}: params must be a BoucWenParams{hint}, got {type(params).__name__} {params!r}"
        )


def as_measurements(zs: Any, n: int) -> list[float | None]:
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
    if isinstance(zs, str | bytes) or not hasattr(zs, "__len__"):
        raise InputError(
            f"zs must be a sequence of measurements (None for a missing sample), one per "
            f"input, got {type(zs).__name__} {zs!r}"
        )
    if len(zs) != n:
        raise InputError(f"zs and us must have the same length, got {len(zs)} and {n}")
    return [None if z is None else finite_scalar(z, "z") for z in zs]


def as_inputs(us: Any) -> list[float]:
    """Validate a record of held inputs as python floats."""
    u = np.asarray(us)
    if u.dtype.kind not in "fiu":
        raise InputError(
            f"us must be a 1-D sequence of numbers (held inputs), got {type(us).__name__} {us!r}"
        )
    u = u.astype(float)
    if u.ndim != 1:
        raise InputError(f"us must be a 1-D sequence of held inputs, got shape {u.shape}")
    if not np.all(np.isfinite(u)):
        k = int(np.flatnonzero(~np.isfinite(u))[0])
        raise InputError(f"u must be finite, got us[{k}] = {u[k]}")
    return u.tolist()


class SampledObserver:
    """Shared machinery of the discrete observers (filterpy-style interface).

    One base serves the 3-state observers (x1, x2, x3) and the 4-state
    disturbance observer (x1, x2, x3, d): with ``n = 4`` the linear part sees
    the lumped ``w = x3 + d`` where the 3-state ones see ``x3``, and ``d`` is
    held in the predict. A subclass sets ``_n``, ``_hysteresis`` and ``kind``
    and, for ``n = 4``, how continuous gains map to ``K`` (the hooks
    ``_check_continuous``, ``_discrete_from`` and ``_observable_K``).

    The step is computed on python floats with the scalar entries of the ZOH
    matrices (one sample costs a few microseconds); :func:`phso_step` and
    :func:`eso_step` are independent array twins of it, checked against it in
    the tests.

    Attributes
    ----------
    x : ndarray, shape (n,)
        Current estimate (x1 displacement, x2 velocity, x3 hysteresis[, d disturbance]).
    x_prior, x_post : ndarray, shape (n,)
        Estimate after the last ``predict`` and after the last ``update``.
    K : ndarray, shape (n,)
        Discrete correction gains.
    gains : ndarray, shape (n,) or None
        Continuous gains the observer was built from (None if built from ``K``).
    y : float
        Last innovation ``z - x_prior[0]`` (0 for a skipped sample).
    z : float or None
        Last measurement.
    u_prev : float
        Input held over the previous sample (V).
    """

    _hysteresis = True
    _n = 3
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
        check_params(params, type(self).__name__)
        require_bounded(params, allow_unbounded)
        self.params = params
        self.dt = check_dt(dt)
        self._zoh = discretize(params, self.dt)
        F, g = self._zoh.F, self._zoh.g
        # the two non-trivial rows of F and g (row 3 is x3+ = h, g3 = 0)
        self._coef = (*F[0].tolist(), *F[1].tolist(), float(g[0]), float(g[1]))
        names = ", ".join(f"l{i + 1}" for i in range(self._n))
        if (gains is None) == (discrete is None):
            raise GainError(
                f"{type(self).__name__}: give either continuous gains ({names}) or "
                "discrete=K, exactly one of them"
            )
        if discrete is None:
            self.gains = self._check_continuous(params, gains)
            self.K = self._discrete_from(params, self.gains, self.dt)
            Ko = self._observable_K(self.K)
            margin, z = schur_margin(params, Ko, self.dt)
            if not margin < 0:
                raise GainError(
                    f"gains l = {self.gains.tolist()} at dt = {self.dt:g} s give discrete gains "
                    f"K = {self.K.tolist()} whose nominal error dynamics (I - K C) F are not "
                    f"Schur stable (max |z|^2 - 1 = {margin:.3g}, poles {np.round(z, 12).tolist()})"
                )
        else:
            self.gains = None
            self.K = self._check_discrete(discrete)
            Ko = self._observable_K(self.K)
            rho = np.abs(np.linalg.eigvals(self._zoh.F - np.outer(Ko, C @ self._zoh.F)))
            if rho.max() >= 1.0:
                raise GainError(
                    f"discrete gains K = {self.K.tolist()} leave the nominal error dynamics "
                    f"unstable (spectral radius {rho.max():.6g} >= 1)"
                )
        self.reset(x0, u_prev=u_prev)

    # gain hooks (3-state defaults) ------------------------------------------------

    @staticmethod
    def _check_continuous(params: BoucWenParams, gains: Any) -> np.ndarray:
        return check_gains(params, gains)

    @staticmethod
    def _discrete_from(params: BoucWenParams, gains: np.ndarray, dt: float) -> np.ndarray:
        return discrete_gains(params, gains, dt)

    @staticmethod
    def _check_discrete(discrete: Any) -> np.ndarray:
        return as_gains(discrete, "discrete gains K")

    @staticmethod
    def _observable_K(K: np.ndarray) -> np.ndarray:
        """The correction of the observable part (x1, x2, x3 [+ d]), shape (3,)."""
        return K

    # state -------------------------------------------------------------------------

    def reset(self, x0: Any = None, *, u_prev: float = 0.0) -> None:
        """Restart from ``x0`` (default zeros) with ``u_prev`` (V) held before the first sample."""
        x = np.zeros(self._n) if x0 is None else state_vector(x0, "x0", self._n)
        self._x = x
        self.x_prior = x.copy()
        self.x_post = x.copy()
        self.u_prev = finite_scalar(u_prev, "u_prev")
        self.y = 0.0
        self.z: float | None = None

    @property
    def x(self) -> np.ndarray:
        """Current estimate, shape (n,).

        Assigning accepts n finite numbers of shape (n,) or filterpy's (n, 1)
        (stored as (n,)); anything else raises :class:`InputError`.
        """
        return self._x

    @x.setter
    def x(self, value: Any) -> None:
        self._x = state_vector(value, "x", self._n)

    @property
    def x_lumped(self) -> np.ndarray:
        """``(x1, x2, x3 [+ d])``, shape (3,): what the linear part (and a controller) sees."""
        x = self._x
        if self._n == 3:
            return x.copy()
        return np.array([x[0], x[1], x[2] + x[3]])

    def _finite(self, xs: list[float]) -> None:
        if not all(math.isfinite(v) for v in xs):
            require_finite_state(self._x, type(self).__name__)

    def predict(self, u: float) -> None:
        """Carry the estimate from ``t_k`` to ``t_{k+1}`` with ``u`` (V) held.

        With the hysteresis model the copy first follows the jump ``u_prev -> u``
        in closed form; then the linear part is propagated exactly (ZOH), with
        ``x3 + d`` in place of ``x3`` for the disturbance observer (``d`` held).
        """
        u = finite_scalar(u, "u")
        xs = self._x.tolist()
        if self._n == 3:
            x1, x2, x3 = xs
            if not (math.isfinite(x1) and math.isfinite(x2) and math.isfinite(x3)):
                require_finite_state(self._x, type(self).__name__)
            d = None
        else:
            self._finite(xs)
            x1, x2, x3, d = xs
        if self._hysteresis:
            x3 = hysteresis_increment(self.params, x3, self.u_prev, u)
        w = x3 if d is None else x3 + d
        f11, f12, f13, f21, f22, f23, g1, g2 = self._coef
        x1n = f11 * x1 + f12 * x2 + f13 * w + g1 * u
        x2n = f21 * x1 + f22 * x2 + f23 * w + g2 * u
        prior = (x1n, x2n, x3) if d is None else (x1n, x2n, x3, d)
        self._x = np.array(prior)
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
            self.x_post = self._x.copy()
            return
        z = finite_scalar(z, "z")
        xs = self._x.tolist()
        if self._n == 3:
            x1, x2, x3 = xs
            if not (math.isfinite(x1) and math.isfinite(x2) and math.isfinite(x3)):
                require_finite_state(self._x, type(self).__name__)
            k1, k2, k3 = self.K.tolist()
            r = z - x1
            post = (x1 + k1 * r, x2 + k2 * r, x3 + k3 * r)
        else:
            self._finite(xs)
            r = z - xs[0]
            post = tuple(xi + ki * r for xi, ki in zip(xs, self.K.tolist(), strict=True))
        self.z = z
        self.y = r
        self._x = np.array(post)
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
        ndarray, shape (N, n)
            The posterior estimates at ``t_1 .. t_N``.
        """
        ul = as_inputs(us)
        zl = as_measurements(zs, len(ul))
        if not ul:
            return np.empty((0, self._n))
        f11, f12, f13, f21, f22, f23, g1, g2 = self._coef
        Kl = self.K.tolist()
        k1, k2, k3 = Kl[:3]
        k4 = Kl[3] if self._n == 4 else 0.0
        xs = self._x.tolist()
        self._finite(xs)
        x1, x2, x3 = xs[:3]
        four = self._n == 4
        d = xs[3] if four else 0.0
        up = self.u_prev
        params, hyst = self.params, self._hysteresis
        out = []
        append = out.append
        for uk, zk in zip(ul, zl, strict=True):
            if hyst:
                x3 = hysteresis_increment(params, x3, up, uk)
            w = x3 + d if four else x3
            x1, x2 = (
                f11 * x1 + f12 * x2 + f13 * w + g1 * uk,
                f21 * x1 + f22 * x2 + f23 * w + g2 * uk,
            )
            prior = (x1, x2, x3, d)
            if zk is not None:
                r = zk - x1
                x1, x2, x3 = x1 + k1 * r, x2 + k2 * r, x3 + k3 * r
                if four:
                    d = d + k4 * r
            append((x1, x2, x3, d))
            up = uk
        res = np.array(out)[:, : self._n]
        self.x_prior = np.array(prior[: self._n])
        self.y = 0.0 if zl[-1] is None else zl[-1] - prior[0]
        self._x, self.x_post, self.u_prev, self.z = res[-1].copy(), res[-1].copy(), up, zl[-1]
        return res

    def as_iosystem(self, name: str | None = None):
        """The continuous form of this observer as a python-control ``NonlinearIOSystem``.

        See :func:`observer_iosystem` (inputs ``u``, ``udot``, ``y``; states and
        outputs ``xhat[0..n-1]``).

        Raises
        ------
        GainError
            The observer was built from discrete gains ``K``, which do not
            define a continuous observer.
        """
        if self.gains is None:
            raise GainError(
                f"{type(self).__name__} was built from discrete gains K; the continuous "
                "form needs continuous gains: build it with gains=..."
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
