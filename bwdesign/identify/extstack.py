"""The base model with extensions a real piezo record may call for.

An :class:`ExtStack` is a :class:`~bwdesign.identify.stack.Stack` whose records see

- an **amplifier lag** ``tau_a`` (s): the voltage at the stage is the commanded
  input through a first-order lag, ``v_{k+1} = e v_k + (1 - e) u_k`` with
  ``e = exp(-dt/tau_a)`` (exact for the held command; the lagged voltage is then
  held per sample for the Bouc-Wen model), ``v_0 = u_0``; it is held fixed in an
  ExtStack and profiled outside (:mod:`bwdesign.identify.extend`);
- **creep**: output terms ``c_i (L_i u - u)`` with ``L_i`` a first-order lag of
  time constant ``CREEP_TAUS[i]`` (unit DC gain, started in steady state): zero
  at DC, so ``a3/a1`` stays the static gain and ``c_i > 0`` is an output that
  keeps growing after a step. The weights ``c_i`` (µm/V) are shared by the records;
- a **drift** of the sensor: ``s_k (t - t_0)`` per record (µm/s).

Creep weights and drift slopes enter linearly: like the offsets they are solved
in closed form (variable projection: the residual and the Jacobian projected on
the complement of their columns), so the optimiser never steps along them. The
Jacobian handed to the covariance is projected on the complement of the creep
and drift columns only (the offsets stay columns): the intervals of the other
coordinates are marginal over the creep weights and drifts.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from scipy.signal import lfilter

from .problem import Problem, delayed_input
from .stack import Stack

__all__ = ["CREEP_TAUS", "ExtConfig", "ExtStack", "creep_response", "first_order_lag"]

#: Creep time constants (s): three, log-spaced between 0.1 s and 10 s.
CREEP_TAUS = (0.1, 1.0, 10.0)


def first_order_lag(u: np.ndarray, dt: float, tau: float) -> np.ndarray:
    """The held input ``u`` through ``1/(tau s + 1)``, sampled (exact; steady at ``u[0]``)."""
    u = np.asarray(u, dtype=float)
    if tau <= 0.0:
        return u.copy()
    e = math.exp(-dt / tau)
    out = np.empty_like(u)
    out[0] = u[0]
    if u.size > 1:
        out[1:], _ = lfilter([1.0 - e], [1.0, -e], u[:-1], zi=[e * u[0]])
    return out


@dataclass(frozen=True)
class ExtConfig:
    """Which extensions a fit uses: amplifier lag (s, 0 = none), creep lags, drift."""

    amp_tau: float = 0.0
    creep_taus: tuple[float, ...] = ()
    drift: bool = False

    @property
    def names(self) -> tuple[str, ...]:
        out = []
        if self.amp_tau > 0:
            out.append("amplifier_lag")
        if self.creep_taus:
            out.append("creep")
        if self.drift:
            out.append("drift")
        return tuple(out)

    @property
    def n_extra(self) -> int:
        """Extra parameters (amplifier lag 1, creep one per lag, drift one per record)."""
        return (self.amp_tau > 0) + len(self.creep_taus)


class ExtStack(Stack):
    """A :class:`Stack` with the extensions of ``config`` (see the module docstring)."""

    def __init__(self, problems: Sequence[Problem], config: ExtConfig, times: list[np.ndarray]):
        super().__init__(problems)
        self.config = config
        self.times = times
        #: the records' delayed inputs before the amplifier lag (set by :meth:`build_ext`)
        self.raw: Sequence[Problem] | None = None
        cols = []
        r_n = self.n_records
        for b in self.blocks():
            c = np.zeros(self.n)
            c[b] = 1.0
            cols.append(c)
        for tau in config.creep_taus:
            cols.append(np.concatenate([creep_response(p.u, p.dt, tau) for p in self.problems]))
        if config.drift:
            for k, b in enumerate(self.blocks()):
                c = np.zeros(self.n)
                c[b] = times[k] - times[k][0]
                cols.append(c)
        self.basis = np.column_stack(cols)
        self.q_all = np.linalg.qr(self.basis)[0]
        extra = self.basis[:, r_n:]
        self.q_extra = np.linalg.qr(extra)[0] if extra.shape[1] else None

    @classmethod
    def build_ext(
        cls, records: Sequence, sign: float, config: ExtConfig, *, delay: int = 0
    ) -> ExtStack:
        """The extended stack of ``records`` (objects with ``t``, ``u``, ``y``, ``dt``)."""
        base = Stack.build(records, sign, delay=delay)
        out = cls._lagged(base.problems, config, [np.asarray(r.t, dtype=float) for r in records])
        out.raw = base.problems
        return out

    @classmethod
    def _lagged(cls, raw: Sequence[Problem], config: ExtConfig, times: list) -> ExtStack:
        problems = [
            Problem(
                first_order_lag(p.u, p.dt, config.amp_tau), p.y, p.dt, p.sign, y_scale=p.y_scale
            )
            for p in raw
        ]
        return cls(problems, config, times)

    def held_jacobian(self, theta: np.ndarray) -> np.ndarray:
        """The residual's derivative in ``log`` of the amplifier lag (held in the fit,
        profiled outside): central differences of the whole extended model, so that
        the intervals of the other coordinates are marginal over the lag."""
        if self.config.amp_tau <= 0 or self.raw is None:
            return super().held_jacobian(theta)
        step = 1e-3
        cols = []
        for sgn in (1.0, -1.0):
            cfg = replace(self.config, amp_tau=self.config.amp_tau * math.exp(sgn * step))
            cols.append(ExtStack._lagged(self.raw, cfg, self.times).residual(theta))
        return ((cols[0] - cols[1]) / (2.0 * step))[:, None]

    # -- the linear extension columns projected out ------------------------------
    def centre(self, x: np.ndarray) -> np.ndarray:
        return x - self.q_all @ (self.q_all.T @ x)

    def _base_residual(self, theta: np.ndarray) -> np.ndarray:
        return super().residual(theta)

    def residual(self, theta: np.ndarray) -> np.ndarray:
        return self.centre(self._base_residual(theta))

    def coefficients(self, theta: np.ndarray) -> np.ndarray:
        """Least-squares coefficients of every extension column (scaled units)."""
        r0 = self._base_residual(theta)
        if not np.all(np.isfinite(r0)):
            return np.zeros(self.basis.shape[1])
        return np.linalg.lstsq(self.basis, -r0, rcond=None)[0]

    def project_offsets(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        theta = theta.copy()
        r0 = self._base_residual(theta)
        if not np.all(np.isfinite(r0)):
            return theta, r0
        c = np.linalg.lstsq(self.basis, -r0, rcond=None)[0]
        for k in range(self.n_records):
            theta[self.offset_index(k)] += c[k]
        return theta, r0 + self.basis @ c

    def offset_index(self, k: int) -> int:
        return 6 if self.n_records == 1 else int(self.i_off[k])

    def jacobian(self, theta: np.ndarray, free: np.ndarray, *, central: bool = False) -> np.ndarray:
        jac = super().jacobian(theta, free, central=central)
        if self.q_extra is None:
            return jac
        return jac - self.q_extra @ (self.q_extra.T @ jac)

    # -- outputs -------------------------------------------------------------------
    def extension_output(self, theta: np.ndarray, coef: np.ndarray | None = None) -> np.ndarray:
        """The creep and drift terms of every sample (µm), offsets excluded."""
        c = self.coefficients(theta) if coef is None else coef
        r_n = self.n_records
        return self.y_scale * (self.basis[:, r_n:] @ c[r_n:])

    def predict_each(self, theta: np.ndarray) -> list[np.ndarray]:
        extra = self.extension_output(theta)
        base = super().predict_each(theta)
        return [m + extra[b] for m, b in zip(base, self.blocks(), strict=True)]

    def predict(self, theta: np.ndarray) -> np.ndarray:
        return np.concatenate(self.predict_each(theta))

    def creep_weights(self, theta: np.ndarray) -> tuple[float, ...]:
        """Creep weights ``c_i`` (µm/V), one per lag."""
        c = self.coefficients(theta)
        r_n = self.n_records
        return tuple(float(self.y_scale * w) for w in c[r_n : r_n + len(self.config.creep_taus)])

    def validation_inputs(
        self, rec, delay: int, theta: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Input the Bouc-Wen part of a held-out record sees, and the known creep output
        (the training weights; a drift is the training record's own, not carried over)."""
        v = first_order_lag(delayed_input(rec.u, delay), rec.dt, self.config.amp_tau)
        known = np.zeros(v.size)
        for tau, w in zip(self.config.creep_taus, self.creep_weights(theta), strict=True):
            known += w * creep_response(v, rec.dt, tau)
        return v, known


def creep_response(u: np.ndarray, dt: float, tau: float) -> np.ndarray:
    """One creep column: ``L u - u`` with ``L`` the first-order lag ``tau`` (zero at DC)."""
    return first_order_lag(u, dt, tau) - u
