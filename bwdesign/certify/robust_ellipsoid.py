"""The common ellipsoid of the robust loop certificate (:mod:`bwdesign.certify.robust`).

:class:`Ellipsoids` holds the scaled LMI blocks of every plant of the box (each
distinct corner block once, an interior block once a solution violates it), solves the
common ellipsoid (:func:`bwdesign.certify.lmi.robust_ellipsoid`) and checks it outside
the solver; :func:`contraction` chooses the contraction per sample; :func:`plant_label`
names a plant by its deviation from the model, for the messages of a box that is not
certified.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.linalg import matrix_balance, solve_discrete_lyapunov

from ..model.params import MODEL_FIELDS, BoucWenParams
from ..validate import real
from .ellipsoid import schur_min_eig, search_log_contraction, solution
from .results import CONTRACTION, Margin

__all__ = ["Ellipsoids", "contraction", "plant_label", "ACTIVE_TOL", "A_GRID", "A_REFINE", "EPS"]

#: Normalised eigenvalue below which an interior block joins the LMI.
ACTIVE_TOL = 1e-9
#: Contraction search: grid points on log(1 - a), then golden-section steps.
A_GRID = 7
A_REFINE = 5
#: The LMI's margin (``>= eps I``), and the larger ones tried when the solver's answer
#: fails the outside check: its own tolerance can leave a block a few 1e-5 negative
#: (paper_experiment, +-5 % box, PHSO: -3.5e-5 at 1e-5, +9e-5 at 1e-4)
EPS = (1e-5, 1e-4, 1e-3)


@dataclass
class Ellipsoids:
    """The scaled LMI blocks of every plant and the solves of the common ellipsoid.

    Corners that differ only in (alpha, beta, gamma) share their blocks (the
    hysteresis enters through the global input bounds): each distinct corner block is
    imposed once, and an interior block only once a solution violates it (``active``,
    kept across the solves of one certificate).
    """

    blocks: list[tuple[np.ndarray, np.ndarray]]
    n_corner: int
    s: np.ndarray
    active: dict[bytes, int] = field(default_factory=dict)
    #: the plant (index into the data) of each block, and each plant's label
    owner: list[int] = field(default_factory=list)
    labels: list[str] = field(default_factory=list)
    #: the LMI margin of the solution :meth:`firm` kept
    margin: float = EPS[0]

    @classmethod
    def build(
        cls, st: Any, data_v: list[dict], data_i: list[dict], W: np.ndarray, nominal: tuple
    ) -> Ellipsoids:
        """The scaled blocks of the plants' ``data`` (corners, then interior points);
        ``st`` the certificate's setup, ``nominal`` the nominal plant's first block."""
        keep = W > 0
        Wk = W[keep]
        # state scaling: balance the nominal loop, then the square root of the diagonal of
        # its steady covariance under the normalised inputs, so that P is O(1)
        A_nom, B_nom = nominal
        _, (s, _) = matrix_balance(A_nom, permute=False, separate=True)
        s = np.asarray(s, float)
        if float(np.max(np.abs(np.linalg.eigvals(A_nom)))) < 1:
            Ab = A_nom * s[None, :] / s[:, None]
            Bb = B_nom[:, keep] * Wk[None, :] / s[:, None]
            X = solve_discrete_lyapunov(Ab, Bb @ Bb.T)
            s = s * np.sqrt(np.maximum(np.diag(X), 1e-12 * float(np.max(np.diag(X)))))

        def scaled(A, B):
            Bs = B[:, keep] * Wk[None, :]
            return A * s[None, :] / s[:, None], Bs / s[:, None]

        blocks_v = [scaled(A, B) for d in data_v for (A, B) in d["blocks"]]
        blocks_i = [scaled(A, B) for d in data_i for (A, B) in d["blocks"]]
        data = data_v + data_i
        owner = [j for j, d in enumerate(data) for _ in d["blocks"]]
        labels = [plant_label(st.params, d["plant"]) for d in data]
        ell = cls(blocks_v + blocks_i, len(blocks_v), s, owner=owner, labels=labels)
        for i, (A, B) in enumerate(blocks_v):
            ell.active.setdefault(A.tobytes() + B.tobytes(), i)
        return ell

    def spectral_radius(self) -> float:
        return max(self.radii())

    def radii(self) -> list[float]:
        return [float(np.max(np.abs(np.linalg.eigvals(A)))) for A, _ in self.blocks]

    def hardest(self) -> str:
        """The plant of the block with the largest spectral radius, and that radius."""
        r = self.radii()
        i = int(np.argmax(r))
        where = "corner" if i < self.n_corner else "interior point"
        return f"{where} {self.labels[self.owner[i]]} (spectral radius {r[i]:.6g})"

    def attempt(self, av: float, c: np.ndarray, eps: float = EPS[0]) -> Any:
        """Solve on the distinct corner blocks plus the violated interior ones, each block
        ``>= eps I``."""
        from . import lmi

        blocks, active = self.blocks, self.active
        while True:
            idx = sorted(active.values())
            sol = lmi.robust_ellipsoid(
                [blocks[i][0] for i in idx],
                [blocks[i][1] for i in idx],
                self.s * c,
                a=av,
                eps=eps,
            )
            if not sol.ok:
                return sol
            Q, lam = solution(sol)
            bad = [
                i
                for i in range(self.n_corner, len(blocks))
                if i not in idx and schur_min_eig(Q, lam, *blocks[i], av) <= ACTIVE_TOL
            ]
            if not bad:
                return sol
            for i in bad:
                active.setdefault(blocks[i][0].tobytes() + blocks[i][1].tobytes(), i)

    def firm(self, sol: Any, av: float, c: np.ndarray, st: Any, data: list[dict]) -> Any:
        """``sol`` if it passes the outside check, else the first solve at the same
        contraction with a larger margin (:data:`EPS`) that does; ``sol`` if none does."""
        self.margin = EPS[0]
        if sol is None or not sol.ok or all(m.passed for m in self.check(sol, av, st, data)[0]):
            return sol
        for eps in EPS[1:]:
            s2 = self.attempt(av, c, eps)
            if s2.ok and all(m.passed for m in self.check(s2, av, st, data)[0]):
                self.margin = eps
                return s2
        return sol

    def check(self, sol: Any, av: float, st: Any, data: list[dict]):
        """The outside check of every block, and the bounds of ``sol``'s ellipsoid.

        Returns ``(margins, peak, dyn)``: ``dyn(c)`` bounds ``|c'z~|`` on the ellipsoid,
        ``peak(i)`` the whole ``|c'z|`` for ``c = statics[i]`` (plus its quasi-static part).
        """
        s = self.s
        Q, lam = solution(sol)
        margins = [Margin("Q > 0", -float(np.linalg.eigvalsh(Q).min()), 0.0)]
        for idx, (A, B) in enumerate(self.blocks):
            ev = schur_min_eig(Q, lam, A, B, av)
            where = "corner" if idx < self.n_corner else "interior"
            label = self.labels[self.owner[idx]]
            margins.append(Margin(f"Schur block {idx} ({where} {label}) > 0", -ev, 0.0))
        gam = float(lam.sum())

        def dyn(c):
            cs = s * c
            return math.sqrt(max(gam, 0.0) * float(cs @ Q @ cs))

        def peak(i):
            # the largest quasi-static part |c' G^-1 w_slow| over the plants
            return dyn(st.statics[i]) + max(float(d["static"][i]) for d in data)

        return margins, peak, dyn


def plant_label(params: BoucWenParams, tp: BoucWenParams) -> str:
    """``tp`` against the model: each parameter that differs, in percent (``nominal``)."""
    out = [
        f"{k} {100 * (getattr(tp, k) / getattr(params, k) - 1):+.3g} %"
        if getattr(params, k)
        else f"{k} = {getattr(tp, k):.6g}"
        for k in MODEL_FIELDS
        if getattr(tp, k) != getattr(params, k)
    ]
    return "[" + ", ".join(out) + "]" if out else "[nominal]"


def contraction(
    ell: Ellipsoids, a: float | None, spec: float, c: np.ndarray, *, first: bool = False
):
    """``(solution, a)``: at the given contraction, or the one with the smallest bound
    (``first``: the fastest feasible contraction of the grid)."""
    if a is not None:
        av = real(a, "a", within=CONTRACTION)
        return ell.attempt(av, c), av
    # the contraction on x = log(1 - a): a coarse grid, then golden section
    rad = spec**2
    lo, hi = math.log(1e-5), math.log(1 - rad)
    best = None
    cache: dict[float, Any] = {}
    if first:
        # the grid from its fast end (the contraction nearest the spectral radius): the
        # first feasible point (the solver may fail at a point between feasible ones, so
        # no bisection)
        for x in np.linspace(lo, hi, A_GRID + 2)[-2:0:-1]:
            av = 1 - math.exp(float(x))
            sol = ell.attempt(av, c)
            if sol.ok:
                return sol, av
        return None, math.nan

    def f(x: float) -> float:
        av = 1 - math.exp(x)
        if x not in cache:
            sol = ell.attempt(av, c)
            cache[x] = (sol, av, sol.objective if sol.ok else math.inf)
        return cache[x][2]

    grid = np.linspace(lo, hi, A_GRID + 2)[1:-1]
    search_log_contraction(f, grid, A_REFINE, lo=lo, hi=hi)
    ok = [v for v in cache.values() if v[0].ok]
    if ok:
        best = min(ok, key=lambda v: v[2])
    return (best[0], best[1]) if best else (None, math.nan)
