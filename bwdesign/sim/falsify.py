"""The worst case a seeded search finds for a loop over an uncertainty box.

A certified bound is an upper bound; a simulated corner is a lower bound only of the
worst case at the corners. :func:`falsify` looks harder, with the same loop, reference
and window the certificate speaks of (steady state, :func:`.corners.simulate_corners`):

1. every corner of the box (with each of the disturbance's worst signals, if any);
2. ``interior`` plants drawn uniformly in the box (``numpy.random.default_rng(seed)``);
3. ``rounds`` of a seeded (1 + lambda) evolution strategy in the box's normalised
   coordinates: ``per_round`` plants around the worst found so far, at a radius halved
   each round, clipped to the box;
4. with sensor noise (``noise_max > 0``; every plant above meets it with a random sign
   per sample), noise *aimed* at the worst plant's largest errors: the response ``h`` of
   ``x1`` to a small noise impulse is measured on that plant (two runs of
   :func:`~.closed_loop.simulate`), and for each of the :data:`AIMS` largest errors
   ``e(K)`` of its noise-free run the noise ``n_k = noise_max sign(e(K)) sign(h_(K-k))``
   pushes ``e(K)`` the same way from every sample before ``K`` (and the opposite sign
   for the largest), all at the bound. Random signs leave ``e(K)`` a sum of terms that
   partly cancel; the aimed noise adds them up (1.59 to 2.24 times the random signs'
   worst case on the bundled stages' nominal loops at 0.01 um).

Every candidate runs in one :func:`.batch.simulate_batch` per stage, so the search costs
a few batches. The result is a *found* worst case: a lower bound of the true worst, to
put beside a certified upper bound (their ratio is the certificate's conservatism). A
found case above a certified bound means the certificate is wrong.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..control.loop import ClosedLoop
from ..errors import InputError
from ..model.params import MODEL_FIELDS, BoucWenParams
from ..model.references import Reference
from ..model.uncertainty import DisturbanceBound, UncertaintyBox
from ..validate import NONNEGATIVE, real
from .closed_loop import simulate
from .corners import simulate_plants, span

__all__ = ["Falsification", "falsify", "AIMS"]

#: Errors of the worst plant's noise-free run the aimed noise is pointed at (step 4).
AIMS = 3
#: The impulse that measures the noise response, as a share of ``noise_max``.
_IMPULSE = 1e-3


@dataclass(frozen=True)
class Falsification:
    """The worst steady errors :func:`falsify` found (lower bounds of the true worst).

    ``worst_maxe``: max ``|x1 - x_d|``; ``worst_estimation_maxe``: max ``|x1hat - x1|``,
    ``|x2hat - x2|``, ``|x3hat - x3|`` (each over every plant tried, not necessarily the
    same plant); ``input_rate_max``: the fastest ``|u'|`` seen, ``input_accel_max`` the
    largest second difference ``|u_k - 2 u_(k-1) + u_(k-2)| / dt^2``; ``worst_plant``: where
    ``worst_maxe`` was found, ``found_by`` how (``"corner"``, ``"interior"``,
    ``"search"`` or ``"noise"``, the aimed noise); ``plants``: how many were simulated
    (the aimed noise's runs included); ``stable``: all of them were.
    """

    worst_maxe: float
    worst_estimation_maxe: tuple[float, float, float]
    input_rate_max: float
    input_accel_max: float
    worst_plant: BoucWenParams
    found_by: str
    plants: int
    stable: bool
    window: tuple[float, float]
    samples: int

    def to_dict(self) -> dict[str, Any]:
        return {
            "worst_maxe": self.worst_maxe,
            "worst_estimation_maxe": list(self.worst_estimation_maxe),
            "input_rate_max": self.input_rate_max,
            "input_accel_max": self.input_accel_max,
            "worst_plant": {k: getattr(self.worst_plant, k) for k in MODEL_FIELDS},
            "found_by": self.found_by,
            "plants": self.plants,
            "stable": self.stable,
            "window": list(self.window),
            "samples": self.samples,
        }


class _Search:
    """The plants tried so far and their outcomes."""

    def __init__(self, loop, box, reference, disturbance, noise_max):
        self.loop, self.box, self.reference, self.dist = loop, box, reference, disturbance
        self.noise_max = noise_max
        self.params = loop.model
        self.bounds = box.check(self.params, bounded=False)  # {name: (lo, hi)}, varying only
        self.names = list(self.bounds)
        self.plants: list[BoucWenParams] = []
        self.how: list[str] = []
        self.window: tuple[float, float] = (0.0, 0.0)
        self.samples = 0
        # per plant: worst error, estimation errors, input rate, stable, input second difference
        self.per_plant: list[tuple[float, np.ndarray, float, bool, float]] = []

    def run(self, plants: list[BoucWenParams], how: str, pattern: Any = None) -> None:
        if not plants:
            return
        res = simulate_plants(self.loop, plants, self.reference, self.dist, self.noise_max, pattern)
        k = len(res.maxe) // len(plants)  # disturbance scenarios per plant
        for i, tp in enumerate(plants):
            sl = slice(i * k, (i + 1) * k)
            st = bool(res.stable[sl].all())
            maxe = float(np.max(res.maxe[sl])) if st else np.inf
            est = np.max(res.estimation_maxe[sl], axis=0) if st else np.full(3, np.inf)
            rate = float(np.max(res.input_rate_max[sl])) if st else np.inf
            accel = float(np.max(res.input_accel_max[sl])) if st else np.inf
            self.plants.append(tp)
            self.how.append(how)
            self.per_plant.append((maxe, est, rate, st, accel))
        self.window, self.samples = tuple(res.window), res.samples

    def coords(self, tp: BoucWenParams) -> np.ndarray:
        return np.array(
            [(getattr(tp, n) - lo) / (hi - lo) * 2 - 1 for n, (lo, hi) in self.bounds.items()]
        )

    def plant(self, u: np.ndarray, label: str) -> BoucWenParams:
        vals = {
            n: lo + (hi - lo) * (float(x) + 1) / 2
            for (n, (lo, hi)), x in zip(self.bounds.items(), np.clip(u, -1, 1), strict=True)
        }
        return self.params.replace(**vals, name=f"{self.params.name}/{label}")

    def worst(self) -> int:
        return int(np.argmax([p[0] for p in self.per_plant]))

    def aim_noise(self) -> None:
        """Step 4 of the module doc, on the worst plant so far (if its runs were stable)."""
        i = self.worst()
        if self.noise_max <= 0 or not np.isfinite(self.per_plant[i][0]):
            return
        tp = self.plants[i]
        duration, window = span(self.reference)
        run = {"duration": duration, "true_params": tp, "window": window}
        base = simulate(self.loop, self.reference, **run)
        if not base.stable:
            return
        n = base.t.size
        inw = (base.t >= base.window[0] - 1e-12) & (base.t <= base.window[1] + 1e-12)
        k0 = int(np.argmax(inw))
        kick = np.zeros(n)
        kick[k0] = _IMPULSE
        hit = simulate(self.loop, self.reference, noise_std=self.noise_max, noise_kind=kick, **run)
        if not hit.stable:
            return
        h = (hit.x[k0:, 0] - base.x[k0:, 0]) / (_IMPULSE * self.noise_max)
        e = np.where(inw, base.e, 0.0)
        patterns = []
        for rank, K in enumerate(_peaks(np.abs(e), AIMS, max(1, int(inw.sum()) // 10))):
            lags = K - np.arange(n)  # sample k's lag before K
            known = (lags >= 0) & (lags < h.size)
            aimed = np.zeros(n)
            aimed[known] = np.sign(h[lags[known]])
            sign = 1.0 if e[K] >= 0 else -1.0
            patterns.append(sign * aimed)
            if rank == 0:
                patterns.append(-sign * aimed)
        self.run([tp] * len(patterns), "noise", np.array(patterns))


def falsify(
    loop: ClosedLoop,
    box: UncertaintyBox,
    reference: Reference,
    *,
    disturbance: DisturbanceBound | None = None,
    interior: int = 16,
    rounds: int = 3,
    per_round: int = 8,
    seed: int = 0,
    noise_max: float = 0.0,
) -> Falsification:
    """Search the box for the loop's worst steady tracking error (see the module doc).

    Parameters
    ----------
    loop : ClosedLoop
    box : UncertaintyBox
    reference : Reference
    disturbance : DisturbanceBound, optional
        Each plant also runs each of :func:`.corners.disturbance_signals`.
    interior, rounds, per_round : int
        Uniform interior plants; rounds of the evolution strategy and plants per round.
    seed : int
    noise_max : float
        Sensor noise at this bound on every plant (:func:`.corners.simulate_plants`:
        ``+-noise_max`` with a seeded random sign per sample), then aimed at the worst
        plant's largest errors (step 4 of the module doc), as a certificate with
        ``|n| <= noise_max`` covers it; 0: noise free.

    Returns
    -------
    Falsification
    """
    for name, v in (("interior", interior), ("rounds", rounds), ("per_round", per_round)):
        if isinstance(v, bool) or not isinstance(v, int) or v < 0:
            raise InputError(f"{name} must be an integer >= 0, got {v!r}")
    if not isinstance(box, UncertaintyBox):
        raise InputError("box must be an UncertaintyBox")
    rng = np.random.default_rng(seed)
    noise_max = real(noise_max, "noise_max", within=NONNEGATIVE)
    s = _Search(loop, box, reference, disturbance, noise_max)
    s.run(box.vertices(loop.model), "corner")
    if s.names:
        s.run(box.sample(loop.model, rng, interior), "interior")
        radius = 0.5
        for r in range(rounds):
            best = s.coords(s.plants[s.worst()])
            steps = rng.uniform(-radius, radius, size=(per_round, len(s.names)))
            s.run([s.plant(best + d, f"search{r}.{i}") for i, d in enumerate(steps)], "search")
            radius /= 2
    s.aim_noise()
    i = s.worst()
    ests = np.array([p[1] for p in s.per_plant])
    return Falsification(
        worst_maxe=float(s.per_plant[i][0]),
        worst_estimation_maxe=tuple(float(x) for x in np.max(ests, axis=0)),
        input_rate_max=float(max(p[2] for p in s.per_plant)),
        input_accel_max=float(max(p[4] for p in s.per_plant)),
        worst_plant=s.plants[i],
        found_by=s.how[i],
        plants=len(s.plants),
        stable=all(p[3] for p in s.per_plant),
        window=s.window,
        samples=s.samples,
    )


def _peaks(values: np.ndarray, count: int, apart: int) -> list[int]:
    """The indices of the ``count`` largest ``values``, each at least ``apart`` from the
    ones before (largest first; fewer where the rest are zero)."""
    order = np.argsort(-values, kind="stable")
    chosen: list[int] = []
    for k in order:
        if values[k] <= 0 or len(chosen) == count:
            break
        if all(abs(int(k) - c) >= apart for c in chosen):
            chosen.append(int(k))
    return chosen
