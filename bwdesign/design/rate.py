"""The input-rate envelope of a robust loop certificate, proved rather than assumed.

:func:`bwdesign.certify_robust` assumes the loop keeps ``|u'| <= E`` and bounds the loop's
own input step in steady state, ``s(E)`` (``details["input_step_bound"] / dt``). When
``s(E) <= E`` the assumption is a fixed point: a loop in its steady set whose rate is
within ``E`` keeps it there, and the certificate says "proved". At the stage's envelope
that is rarely so (the bound is 1.4 to 5.8 times the envelope on the bundled stages);
further out it can be, at the price of a larger tracking bound, because the hysteresis
channels grow with ``E``. :func:`prove_rate` looks for that point: it certifies at
``E``, then at ``s(E)``, then along the secant of ``s(E) - E`` (``s`` is close to affine
in ``E``: the hysteresis jumps and the slope interval grow with it), each step checked
by the certificate itself. Measured on the nominal loops with the report's
second-difference envelope (``reports/robust_bounds``): paper_experiment's rate is proved
at 415.1 V/s with the same tracking bound as at its 396.9 V/s (0.0302 um),
paper_simulation_corrected's at 537.9 V/s (0.0160 um, the same too), the stack's at
6 661 V/s (0.0304 instead of 0.0152 um). Without that envelope: the stack at 6 710 V/s,
paper_experiment at 1 069 V/s (0.385 um), paper_simulation_corrected not at all.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ..certify.robust import RobustCertificate, certify_robust
from ..control.loop import ClosedLoop
from ..errors import InputError
from ..model.references import Reference
from ..model.uncertainty import DisturbanceBound, UncertaintyBox

__all__ = ["RateProof", "prove_rate"]

#: Each secant step aims this factor beyond the predicted fixed point, so that rounding
#: and the bound's slight curvature do not leave it just short.
_AIM = 1.001


@dataclass(frozen=True)
class RateProof:
    """What :func:`prove_rate` found.

    Attributes
    ----------
    proved : bool
        ``certificate`` holds and proves its own envelope (``details["rate_proved"]``).
    envelope : float
        The envelope of ``certificate`` (input unit per s).
    certificate : RobustCertificate
        The last certificate computed (the proving one when ``proved``).
    steps : tuple of (float, float)
        Each envelope tried and the certificate's bound on the loop's input rate there
        (``nan`` where it did not hold).
    reason : str
        Why the search stopped.
    """

    proved: bool
    envelope: float
    certificate: RobustCertificate
    steps: tuple[tuple[float, float], ...]
    reason: str

    def to_dict(self) -> dict[str, Any]:
        return {
            "proved": self.proved,
            "envelope": self.envelope,
            "steps": [list(s) for s in self.steps],
            "reason": self.reason,
            "certificate": self.certificate.to_dict(),
        }


def prove_rate(
    loop: ClosedLoop,
    *,
    uncertainty: UncertaintyBox,
    udot_max: float,
    reference: Reference,
    noise_max: float = 0.0,
    disturbance: DisturbanceBound | None = None,
    iterations: int = 8,
    uddot_max: float | None = None,
) -> RateProof:
    """Search the envelope at which the robust loop certificate proves its own input rate.

    Parameters
    ----------
    loop, uncertainty, reference, noise_max, disturbance, uddot_max
        As for :func:`bwdesign.certify_robust`; ``uddot_max``, the second-difference
        envelope, stays an assumption at every envelope tried (it is not searched).
    udot_max : float
        The first envelope tried (V/s), usually the stage's.
    iterations : int
        Certificates computed at most (each is one :func:`~bwdesign.certify_robust`).

    Returns
    -------
    RateProof
        ``proved`` with the certificate at the envelope it proves, or not, with the
        reason: a certificate that does not hold, a rate bound growing at least as
        fast as the envelope (no fixed point), or the iterations spent.

    Examples
    --------
    >>> from bwdesign import ClosedLoop, UncertaintyBox, load_config
    >>> from bwdesign.design import digital_tuning
    >>> cfg = load_config("stack_actuator_800hz")
    >>> loop = ClosedLoop.from_config(cfg, observer="phso",
    ...                               law=digital_tuning(cfg.plant, cfg.dt), saturate=False)
    >>> r = prove_rate(loop, uncertainty=UncertaintyBox.from_dict({}),
    ...                udot_max=cfg.envelope().udot_max, reference=cfg.reference)
    >>> r.proved, round(r.envelope), r.certificate.details["rate_proved"]
    (True, 6710, True)
    """
    if isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 1:
        raise InputError(f"iterations must be an integer >= 1, got {iterations!r}")
    steps: list[tuple[float, float]] = []
    env = float(udot_max)
    for _ in range(iterations):
        rc = certify_robust(
            loop,
            uncertainty=uncertainty,
            udot_max=env,
            reference=reference,
            noise_max=noise_max,
            disturbance=disturbance,
            uddot_max=uddot_max,
        )
        dt = rc.details.get("dt", loop.dt)
        if not rc.holds:
            steps.append((env, math.nan))
            return RateProof(False, env, rc, tuple(steps), f"at {env:.6g}: {rc.status}")
        rate = rc.details["input_step_bound"] / dt
        steps.append((env, rate))
        if rc.details["rate_proved"]:
            return RateProof(True, env, rc, tuple(steps), f"proved at {env:.6g}: {rate:.6g}")
        if len(steps) == 1:
            env = rate  # the rate this certificate allows: the next guess
            continue
        (e0, s0), (e1, s1) = steps[-2], steps[-1]
        slope = (s1 - s0) / (e1 - e0) if e1 != e0 else math.inf
        if not slope < 1:
            why = (
                f"no fixed point: the rate bound grows as fast as the envelope or faster "
                f"(slope {slope:.3g} between {e0:.6g} and {e1:.6g})"
            )
            return RateProof(False, env, rc, tuple(steps), why)
        env = _AIM * (s1 - slope * e1) / (1 - slope)
    return RateProof(
        False, steps[-1][0], rc, tuple(steps), f"not proved in {iterations} certificates"
    )
