"""Observer gains chosen against an uncertainty box: the robust observer synthesis.

The LMI is the robust observer certificate's inequality
(:func:`bwdesign.certify.certify_robust_observer`) with the gain as a variable; the
gains it returns are re-certified by that certificate before they are called feasible.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..certify.checks import continuous_equivalent
from ..certify.ellipsoid import search_log_contraction
from ..certify.results import OUTPUT_ROW
from ..certify.robust_observer import (
    BoxSampling,
    RobustObserverCertificate,
    RobustObserverProblem,
    certify_robust_observer,
    certify_robust_observer_discrete,
    robust_observer_problem,
)
from ..errors import GainError, InputError
from ..model.params import BoucWenParams
from ..model.plant import check_sample_time
from ..model.uncertainty import DisturbanceBound, UncertaintyBox
from ..validate import POLE_RADIUS, real

__all__ = ["RobustObserverSynthesis", "synthesize_robust_observer"]

#: Contractions per sample tried first by the synthesis (then refined).
_GRID = (0.5, 0.8, 0.9, 0.95, 0.98, 0.99, 0.995, 0.998)


@dataclass(frozen=True)
class RobustObserverSynthesis:
    """Observer gains minimising the certified bound over a box, or a clear "no".

    Attributes
    ----------
    feasible : bool
        Gains were found *and* :func:`certify_robust_observer` certified them.
    gains : tuple of 3 floats or None
        The exact continuous equivalent of ``K`` (1/s, 1/s^2, 1/s), ``None`` when the
        discrete poles have none (the reason says so).
    discrete_gains : tuple of 3 floats or None
        ``K`` (rounded to 10 significant digits, the numbers re-certified).
    certificate : RobustObserverCertificate or None
        The re-certification (its bounds are the ones to quote).
    target : str
        ``"x1"`` or ``"x3"``: the estimation error whose bound was minimised.
    lmi_bound : float or None
        The bound the LMI reached (length unit), before the re-certification.
    reason : str
    solver, status : str
    """

    feasible: bool
    gains: tuple[float, float, float] | None
    discrete_gains: tuple[float, float, float] | None
    certificate: RobustObserverCertificate | None
    target: str
    lmi_bound: float | None
    reason: str
    solver: str = ""
    status: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "feasible": self.feasible,
            "gains": None if self.gains is None else list(self.gains),
            "discrete_gains": None if self.discrete_gains is None else list(self.discrete_gains),
            "certificate": None if self.certificate is None else self.certificate.to_dict(),
            "target": self.target,
            "lmi_bound": self.lmi_bound,
            "reason": self.reason,
            "solver": self.solver,
            "status": self.status,
        }


def synthesize_robust_observer(
    params: BoucWenParams,
    *,
    dt: float,
    uncertainty: UncertaintyBox,
    udot_max: float,
    input_range: tuple[float, float],
    noise_max: float = 0.0,
    target: str = "x3",
    pole_radius: float | None = None,
    sampling: BoxSampling | None = None,
    disturbance: DisturbanceBound | None = None,
) -> RobustObserverSynthesis:
    """Discrete PHSO gains minimising the certified steady estimation-error bound over a box.

    The LMI :func:`bwdesign.certify.lmi.robust_observer_synthesis` is the certificate's
    inequality in the posterior form with ``Y = P K`` (affine in ``(P, Y, lam)`` for a
    fixed contraction ``a``, searched by golden section on ``log(1 - a)``), in the state
    scaling ``diag(1, sqrt(a1), 1)`` of the nominal sampled synthesis. With
    ``pole_radius`` (rad/s) the nominal discrete poles are kept in the disk ``|z - 1| <
    1 - exp(-pole_radius dt)`` (as :func:`bwdesign.synthesize`: it keeps them off the
    negative real axis, so the exact continuous equivalent of ``K`` exists). ``K`` is
    rounded to 10 significant digits and re-certified by
    :func:`certify_robust_observer` (with the continuous equivalent when it exists,
    else :func:`~bwdesign.certify.robust_observer.certify_robust_observer_discrete` of
    ``K``) before it is called feasible.

    Parameters
    ----------
    params, dt, uncertainty, udot_max, input_range, noise_max, sampling, disturbance
        As :func:`certify_robust_observer`.
    target : {"x3", "x1"}
        The estimation error whose certified bound is minimised.
    pole_radius : float, optional
        Pole-disk radius (rad/s); default none (any Schur-stable ``K``).

    Returns
    -------
    RobustObserverSynthesis
    """
    if target not in ("x1", "x3"):
        raise InputError(f"target must be 'x1' or 'x3', got {target!r}")
    dt = check_sample_time(params, dt)
    opts = {
        "dt": dt,
        "uncertainty": uncertainty,
        "udot_max": udot_max,
        "input_range": input_range,
        "noise_max": noise_max,
        "sampling": sampling,
        "disturbance": disturbance,
    }
    pb = robust_observer_problem(params, **opts)
    disk = None
    if pole_radius is not None:
        R = real(pole_radius, "pole_radius (rad/s)", within=POLE_RADIUS)
        disk = (1.0, -math.expm1(-R * dt))
    if pb.refused or not all(math.isfinite(v) for v in pb.input_bounds.values()):
        why = pb.refused or "an input bound is infinite (the hysteresis mismatch at this rate)"
        return RobustObserverSynthesis(
            False, None, None, None, target, None, f"not certified: {why}"
        )
    T = np.array([1.0, math.sqrt(params.a1), 1.0])
    cache = _synthesis_lmis(pb, T, target, disk)
    ok = [v for v in cache.values() if v[0].ok]
    if not ok:
        last = next(iter(cache.values()))[0]
        return RobustObserverSynthesis(
            False,
            None,
            None,
            None,
            target,
            None,
            f"the synthesis LMI has no solution for any contraction tried ({last.status})",
            last.solver,
            last.status,
        )
    sol, obj, av = min(ok, key=lambda v: v[1])
    opts["a"] = av  # re-certify at the synthesis' contraction (its P is feasible there)
    P = np.asarray(sol["P"])
    Ks = np.linalg.solve((P + P.T) / 2, np.asarray(sol["Y"]).reshape(3))
    K = tuple(float(f"{v:.10g}") for v in T * Ks)
    gains, cert, note = _recertify(params, K, opts)
    bound = (
        None
        if not cert.holds
        else (cert.x3_estimation_bound if target == "x3" else cert.estimation_bound)
    )
    reason = (
        f"K = ({', '.join(f'{k:.6g}' for k in K)}) certified over the box: steady "
        f"|{target}hat - {target}| <= {bound:.4g} (length unit){note}"
        if cert.holds
        else f"the synthesised gains did not pass re-certification ({cert.status}){note}"
    )
    return RobustObserverSynthesis(
        feasible=cert.holds,
        gains=None if gains is None else tuple(float(g) for g in gains),
        discrete_gains=K,
        certificate=cert,
        target=target,
        lmi_bound=math.sqrt(max(obj, 0.0)),
        reason=reason,
        solver=sol.solver,
        status=sol.status,
    )


def _synthesis_lmis(
    pb: RobustObserverProblem, T: np.ndarray, target: str, disk: tuple[float, float] | None
) -> dict[float, Any]:
    """The synthesis LMI over the contraction search: ``{log(1 - a): (sol, objective, a)}``.

    Solved in the state scaling ``T = diag(1, sqrt(a1), 1)``; the objective is the
    squared peak of the ``target`` error (``inf`` where the solve failed).
    """
    from ..certify import lmi

    Fs = pb.F * T[None, :] / T[:, None]
    Bs = pb.Bw / T[:, None]
    c = T * (OUTPUT_ROW if target == "x1" else np.eye(3)[2])
    cache: dict[float, Any] = {}

    def f(x: float) -> float:
        if x not in cache:
            sol = lmi.robust_observer_synthesis(
                Fs, Bs, c, rho=pb.rho, a=1 - math.exp(x), noise=pb.noise, disk=disk
            )
            cache[x] = (sol, sol.objective if sol.ok else math.inf, 1 - math.exp(x))
        return cache[x][1]

    search_log_contraction(f, [math.log(1 - a) for a in _GRID], 5)
    return cache


def _recertify(
    params: BoucWenParams, K: tuple[float, ...], opts: dict[str, Any]
) -> tuple[np.ndarray | None, RobustObserverCertificate, str]:
    """``(continuous gains or None, certificate, note)`` of the rounded synthesised ``K``.

    Certified with its exact continuous equivalent when one exists and is admissible,
    else with ``certify_robust_observer_discrete``.
    """
    with warnings.catch_warnings():  # logm's accuracy note: the result is verified anyway
        warnings.simplefilter("ignore", RuntimeWarning)
        gains = continuous_equivalent(params, K, opts["dt"])
    try:
        if gains is not None:
            cert = certify_robust_observer(params, gains, **opts)
        else:
            cert = certify_robust_observer_discrete(params, K, **opts)
    except GainError as err:  # continuous equivalent outside the Hurwitz conditions (4)
        gains = None
        cert = certify_robust_observer_discrete(params, K, **opts)
        note = f" (its continuous equivalent is not admissible: {err})"
    else:
        note = (
            "" if gains is not None else "; the discrete poles have no exact continuous equivalent"
        )
    return gains, cert, note
