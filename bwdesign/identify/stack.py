"""Several records in one fit: one Bouc-Wen parameter set, an offset and initial state each.

The fit vector of a :class:`Stack` of ``R`` records is the six shared model
coordinates of :mod:`bwdesign.identify.problem` (gain, lag, resonance, alpha,
beta, shape) followed by four coordinates per record (offset, h0, x1_0, x2_0):
length ``6 + 4 R``; with one record it is exactly a :class:`Problem`'s vector.
Residuals are stacked over the records (each on its own sample time); in the
Jacobian the shared columns are the records' columns one above the other and
the per-record columns are block-diagonal. All records share one output scale
(the pooled standard deviation about each record's mean), so the misfit is the
sum of squares in µm over every sample: records logged with the same sensor
weigh by their sample counts. A stack of one record delegates to its problem.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .problem import IA, IK, IOFF, Problem, delayed_input

__all__ = ["Stack", "SHARED"]

#: Number of shared coordinates (log_gain .. shape); the rest are per record.
SHARED = 6
_LOCAL = 4


class Stack:
    """Residuals and Jacobian of several records sharing the model's six coordinates.

    Parameters
    ----------
    problems : sequence of Problem
        One per record, built with a common ``y_scale`` (see :meth:`build`).
    """

    def __init__(self, problems: Sequence[Problem]):
        self.problems = list(problems)
        self.n_records = len(self.problems)
        self.size = SHARED + _LOCAL * self.n_records
        self.sign = self.problems[0].sign
        self.y_scale = self.problems[0].y_scale
        sizes = [p.u.size for p in self.problems]
        self.edges = np.concatenate(([0], np.cumsum(sizes)))
        self.n = int(self.edges[-1])
        #: smallest sample time (the highest Nyquist frequency of the records)
        self.dt = min(p.dt for p in self.problems)
        #: longest record (s)
        self.duration = max(p.u.size * p.dt for p in self.problems)
        self.u_range = float(
            max(p.u.max() for p in self.problems) - min(p.u.min() for p in self.problems)
        )
        first = SHARED + _LOCAL * np.arange(self.n_records)
        #: indices of each record's offset, h0, x1_0 and x2_0 in the fit vector
        self.i_off, self.i_z, self.i_e1, self.i_e2 = first, first + 1, first + 2, first + 3

    @classmethod
    def build(
        cls,
        records: Sequence,
        sign: float,
        *,
        delay: int = 0,
        window: int | None = None,
    ) -> Stack:
        """The stack of ``records`` (objects with ``u``, ``y``, ``dt``) for an input delay.

        ``window``: only the first ``window`` samples of each record (start grids).
        """
        parts = [(delayed_input(r.u, delay)[:window], r.y[:window], r.dt) for r in records]
        if len(parts) == 1:
            return cls([Problem(*parts[0], sign)])
        dev = np.concatenate([y - np.mean(y) for _, y, _ in parts])
        scale = float(np.sqrt(np.mean(dev * dev))) or 1.0
        return cls([Problem(u, y, dt, sign, y_scale=scale) for u, y, dt in parts])

    # -- coordinates ---------------------------------------------------------
    def local(self, theta: np.ndarray, k: int) -> np.ndarray:
        """The ten-coordinate vector of record ``k``."""
        if self.n_records == 1:
            return theta
        j = SHARED + _LOCAL * k
        return np.concatenate((theta[:SHARED], theta[j : j + _LOCAL]))

    def expand(self, theta10: np.ndarray) -> np.ndarray:
        """A ten-coordinate vector (or mask) repeated for every record's own coordinates."""
        if self.n_records == 1:
            return np.array(theta10)
        return np.concatenate((theta10[:SHARED], np.tile(theta10[SHARED:], self.n_records)))

    def blocks(self) -> list[slice]:
        """Rows of each record in the stacked residual."""
        return [slice(int(a), int(b)) for a, b in zip(self.edges[:-1], self.edges[1:], strict=True)]

    def centre(self, x: np.ndarray) -> np.ndarray:
        """``x`` (residual or Jacobian rows) minus each record's mean: the offsets projected out."""
        if self.n_records == 1:
            return x - x.mean(axis=0)
        out = np.array(x, dtype=float)
        for b in self.blocks():
            out[b] -= out[b].mean(axis=0)
        return out

    def project_offsets(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each record's offset at its best value (the mean misfit), and the centred residual."""
        theta = theta.copy()
        r = self.residual(theta)
        for k, b in enumerate(self.blocks()):
            m = float(np.mean(r[b])) if np.all(np.isfinite(r[b])) else 0.0
            theta[IOFF if self.n_records == 1 else self.i_off[k]] -= m
            r[b] -= m
        return theta, r

    def validation_inputs(
        self, rec, delay: int, theta: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Input the model of a held-out record sees, and the output part known in advance
        (none for the base model; see :class:`bwdesign.identify.extstack.ExtStack`)."""
        del theta
        u = delayed_input(rec.u, delay)
        return u, np.zeros(u.size)

    # -- model ---------------------------------------------------------------
    def predict_each(self, theta: np.ndarray) -> list[np.ndarray]:
        """Model output of every record (µm)."""
        return [p.predict(self.local(theta, k)) for k, p in enumerate(self.problems)]

    def predict(self, theta: np.ndarray) -> np.ndarray:
        """Model output of all records, one after the other (µm)."""
        if self.n_records == 1:
            return self.problems[0].predict(theta)
        return np.concatenate(self.predict_each(theta))

    def residual(self, theta: np.ndarray) -> np.ndarray:
        """Stacked scaled residual ``(model - measured) / y_scale``."""
        if self.n_records == 1:
            return self.problems[0].residual(theta)
        return np.concatenate(
            [p.residual(self.local(theta, k)) for k, p in enumerate(self.problems)]
        )

    def jacobian(self, theta: np.ndarray, free: np.ndarray, *, central: bool = False) -> np.ndarray:
        """Stacked Jacobian in the ``free`` coordinates (shared columns: the records' one
        above the other; per-record columns block-diagonal)."""
        if self.n_records == 1:
            return self.problems[0].jacobian(theta, free, central=central)
        jac = np.zeros((self.n, self.size))
        for k, (p, b) in enumerate(zip(self.problems, self.blocks(), strict=True)):
            lf = self.local(free, k)
            cols = np.concatenate((np.arange(SHARED), SHARED + _LOCAL * k + np.arange(_LOCAL)))
            jac[b, cols[lf]] = p.jacobian(self.local(theta, k), lf)
        return jac[:, free]

    def held_jacobian(self, theta: np.ndarray) -> np.ndarray:
        """Residual derivatives in coordinates held during the fit but estimated from the
        data (none here; see :class:`bwdesign.identify.extstack.ExtStack`): ``(n, 0)``."""
        del theta
        return np.zeros((self.n, 0))

    def unit_hysteresis(self, theta: np.ndarray) -> list[np.ndarray]:
        """Each record's hysteresis path for ``alpha = 1``."""
        return [p.unit_hysteresis(self.local(theta, k)) for k, p in enumerate(self.problems)]

    def project(
        self, theta: np.ndarray, h_unit: list[np.ndarray] | None = None
    ) -> tuple[float, np.ndarray]:
        """Best gain and alpha (shared) and offsets and initial states (per record) for the
        nonlinear part of ``theta`` by one linear least-squares solve over all records."""
        if h_unit is None:
            h_unit = self.unit_hysteresis(theta)
        if self.n_records == 1:
            return self.problems[0].project(theta, h_unit[0])
        r_n = self.n_records
        basis = np.zeros((self.n, 2 + 3 * r_n))
        for k, (p, b) in enumerate(zip(self.problems, self.blocks(), strict=True)):
            bk = p.linear_basis(self.local(theta, k), h_unit[k])
            basis[b, :2] = bk[:, :2]
            basis[b, 2 + 3 * k : 5 + 3 * k] = bk[:, 2:]
        y = np.concatenate([p.y for p in self.problems])
        coef, *_ = np.linalg.lstsq(basis, y, rcond=None)
        th = theta.copy()
        if coef[0] <= 0 or coef[1] <= 0:
            return math.inf, th
        r = basis @ coef - y
        th[IK], th[IA] = math.log(coef[0]), math.log(coef[1])
        for k, p in enumerate(self.problems):
            c_off, c1, c2 = coef[2 + 3 * k : 5 + 3 * k]
            th[self.i_off[k]] = (c_off - p.y_mean) / self.y_scale
            th[self.i_e1[k]] = c1 / self.y_scale
            th[self.i_e2[k]] = c2 / self.y_scale
        return float(r @ r) / self.y_scale**2, th

    def project_many(self, thetas: list[np.ndarray]) -> list[tuple[float, np.ndarray]]:
        """:meth:`project` of each of ``thetas`` (one record: computed together, see
        :meth:`bwdesign.identify.problem.Problem.project_many`)."""
        if self.n_records == 1:
            return self.problems[0].project_many(thetas)
        return [self.project(t) for t in thetas]
