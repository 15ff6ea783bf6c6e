"""Robust certificates of the sampled tracking loop over an uncertainty box.

The loop is the one :func:`bwdesign.sim.simulate_batch` runs: the exact ZOH plant
with the *true* parameters ``theta`` (a point of the :class:`~bwdesign.UncertaintyBox`),
the sampled PHSO (predict/update, gain ``K = discrete_gains(model, l, dt)``) and the
discrete eq. (12) law (optionally with integral action and the compensated
one-sample delay) both built on the *model*. Nothing here assumes the model is
right.

Error system
------------
State ``z = (delta1, delta2, e1, e2, e3[, q][, u~])``: the tracking error
``delta = (x1 - x_d, x2 - x_d')``, the prior observer error ``e = xhat - x``, the
integrator and (with the delay) the applied input minus ``u* = ff + Kx . (x_d, x_d', x3)``.
One step is exactly (no approximation, no saturation, no estimate clipping)::

    e+  = (I - K C) e + K n                        (posterior, n the sensor noise)
    e'  = Fm D(rho) e+ + Fm e3 dh + (Fm - Fv)[x12; x3 + j] + (gm - gv) u
    delta' = Fv[x12; x3 + j] + gv u - (x_d, x_d')(k+1)

with ``D(rho) = diag(1, 1, rho)``, ``rho`` the slope of the model's hysteresis jump
map (:func:`rho_interval`, time varying), ``j`` the plant's hysteresis increment,
``dh`` the model-minus-plant increment at the same ``x3`` and ``x12 = (x_d, x_d') +
delta``. The model error is an *input driven by the state and the reference*:
its state-dependent part ``(Fm - Fv)[:, :2] delta`` stays in the vertex's system
matrix, the rest is exogenous: the reference terms (bounded at every time ``t >= 0`` per
vertex by :func:`~bwdesign.model.reference_cover.sup_abs`), ``|x3| <= h_max``,
``|j| <= hi |du|`` (``hi = alpha + (beta - gamma) h_max``, the largest slope of the jump,
:func:`~bwdesign.model.plant.hysteresis_slope_range`),
``|dh| <= (|dalpha| + (|dbeta| + |dgamma|) h_max) |du| exp((|beta| + |gamma|) |du|)``
(Gronwall) with ``|du| <= udot_max dt``, and ``|n| <= noise_max``.

Slow inputs, fast inputs
------------------------
Write one step as ``z+ = A(rho_k) z + w_slow,k + B_f f_k``: ``w_slow = B_ref r_k +
b_x3 x3_k`` (the reference terms and the plant's hysteresis state, which move little
per sample) and ``f = (j, dh, n)``. Per plant (it is constant in time) take
``G = I - A(rho_c)`` at the middle ``rho_c`` of the ``rho`` interval (``A`` is
affine in ``rho``) and ``z~ = z - G^-1 w_slow``. Then exactly::

    z~+ = A(rho_k) z~ + (rho_k - rho_c) E G^-1 w_slow,k - G^-1 (w_slow,k+1 - w_slow,k) + B_f f_k

with ``E = dA/drho`` and ``x3_{k+1} - x3_k = j_k``. The ellipsoid is certified for
``z~``, whose inputs are the *increments* of the reference terms (bounded at every
time by ``sup_abs``), the ``rho`` coupling and the fast inputs; the quasi-static part
``c' G^-1 w_slow`` is bounded the same way and added to each peak.
A loop that rejects a slowly varying model error (integral action, the PHDO's
disturbance state) thus gets the credit the arbitrary-signal bound denied it.

The jump ``j`` enters ``z~`` through ``b_e = B_j - G^-1 b_x3``. With ``uddot_max`` its
change from one sample to the next is bounded too
(:func:`~bwdesign.model.plant.hysteresis_jump_change_bound`), and the same split with
``Q = G^-1 b_e`` is exact: ``z~ = z' + Q j_k`` with ``z'+ = A(rho_k) z' + (rho_k - rho_c) E Q
j_k - Q (j_{k+1} - j_k) + ...``. The certificate computes the per-plant peak-to-peak
bounds with the jump both ways, fast and slow, and keeps the smaller
(``details["jump_input"]``); a loop with integral action rejects a slow jump. The
fast treatment takes the change bound too where it is finite: its peak-to-peak bounds
are then those of an input with ``|j| <= J`` and ``|j_(k+1) - j_k| <= dJ`` at once
(:func:`.peak.l1_bounded_change`, a dual bound evaluated in numpy, no solver), never
above the plain fast bound; both treatments are still computed and the smaller kept. For
the PHDO ``rho = 1`` is fixed and there is no coupling term.

The input disturbance (``disturbance=DisturbanceBound(input_max, rate_max)``)
-----------------------------------------------------------------------------
What the model does not explain, as ``x2' = ... + a3 (u + d)`` on the true plant,
``|d| <= input_max``, ``|d'| <= rate_max``; the observer and the law do not see it.
Over sample ``k`` the plant's step gains ``g_true d_k + r_k`` (``d_k = d(t_k)`` held,
``g_true`` the true ZOH input column) in ``delta`` and the same with a minus sign in
``e``. The held part is slow: ``b_d d_k`` joins ``w_slow``, so its quasi-static part
``|c' G^-1 b_d| input_max`` is added to each peak, its increment ``-G^-1 b_d (d_{k+1} -
d_k)`` with ``|d_{k+1} - d_k| <= rate_max dt`` is an input of the ellipsoid, and (PHSO)
its ``rho`` coupling joins the state channels. ``r`` is what a ``d`` moving within the
sample adds to the held one, ``int_0^dt e^{A(dt-s)} b (d(t_k + s) - d_k) ds``: the
energy ``a1 x1^2 + x2^2`` of the free plant does not grow (``a1 > 0``, ``a2 >= 0``),
so ``|r1| <= rate_max |a3| dt^3 / 6`` and ``|r2| <= rate_max |a3| dt^2 / 2``, two fast
inputs. A disturbance held over each sample (the simulators' ``input_disturbance``)
is covered with room to spare. With no disturbance every added channel is 0 and
is dropped: the certificate is the one without it.

The disturbance observer (``observer="phdo"``, gains ``(l1, l2, 0, l3)``)
------------------------------------------------------------------------
Its law uses the lumped ``x3hat + dhat``; its linear part sees only ``w = x3 + d``.
With ``l3 = 0`` the hysteresis copy ``x3hat`` runs on the model alone, so it stays
in the model's range and ``|e3| <= h_max(model) + h_max(plant)`` for every input.
The lumped error ``(e1, e2, ew = e3 + ed)`` then obeys the error system above with
``K`` the lumped gain ``(k1, k2, k3 + k4)``, ``rho = 1`` and one more input beside
``dh``: ``(rho_k - 1) e3``, ``|.| <= (1 - rho_lo)(h_max(model) + h_max(plant))``.
That is what is certified (the lumped estimate, not ``x3hat`` and ``dhat``
separately, which converge only while the input moves). The ``(rho_k - 1) e3``
input is fast (it follows ``du``), so the bound cannot credit the disturbance state
for it: that part of the PHDO's bound stays conservative.

The envelope is an assumption
-----------------------------
``rho``, ``j`` and ``dh`` are bounded through ``|du| <= udot_max dt``: the
certificate holds for a loop whose input keeps that envelope; it does not prove
that the loop does. ``details["input_step_bound"]`` is the bound this certificate
gives on ``|u_{k+1} - u_k|`` (from the same ellipsoid, with ``u = cu' z + su' s``);
it is far above the envelope in practice (the ellipsoid is shaped for the tracking
error), so the report and the robust design check the envelope on the simulated
corners instead. With ``uddot_max``, a second envelope on the input's second
differences, ``|j|`` is bounded by :func:`~bwdesign.model.plant.hysteresis_jump_bound`
of the box's corners (the jump's slope is high only just after the input turns, where
its steps are small) instead of ``hi |du|``; that envelope is always an assumption.

Certificate
-----------
One quadratic Lyapunov function ``V = z'Pz`` for every corner of the box and both
ends of ``rho``: ``V(z+) <= a V(z) + (1 - a) sum lam_j w_j^2`` (LMI
:func:`bwdesign.certify.lmi.robust_ellipsoid`). *Common*, not parameter-dependent,
because ``rho_k`` changes every sample (a ``P(rho)`` is not a Lyapunov function
for a time-varying ``rho``), and one ``P`` for all ``theta`` keeps the program a
plain vertex LMI. It certifies: the loop's error converges at rate
``-ln(a) / (2 dt)`` into ``{z'Pz <= 1}`` (inputs normalised), so in steady state
``|x1 - x_d| <= sqrt(c'P^-1 c)`` and likewise for the estimation errors. The ZOH
matrices are not affine in ``(a1, a2, a3)``: the LMI covers the convex hull of the
corner matrices, and the result is re-checked with the same ``P`` at seeded interior
points of the box (``interior_samples``), whose input bounds are included; an interior
block the solution violates joins the LMI and the program is solved again. Corners
that differ only in the hysteresis parameters share their blocks (those parameters
enter through the global input bounds), so each distinct block is imposed once: 16
blocks instead of 128 for a full six-parameter box.

Numerics: the state is balanced (:func:`scipy.linalg.matrix_balance` of the nominal
loop matrix), the inputs normalised to ``|w| <= 1``; every LMI block is re-checked
with ``numpy.linalg.eigvalsh`` outside the solver (``min eig > 0``), and the bound is
recomputed from ``P`` with numpy. Solver trouble is a status, never a certificate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..control.controllers import DiscreteTrackingController
from ..control.loop import ClosedLoop
from ..errors import InputError
from ..memo import Memo
from ..model.params import BoucWenParams, require_bounded
from ..model.plant import (
    discretize,
    hysteresis_jump_bound,
    hysteresis_jump_change_bound,
    hysteresis_slope_range,
)
from ..model.reference_cover import require_coverable, sup_abs
from ..model.references import Reference
from ..model.uncertainty import DisturbanceBound, UncertaintyBox, disturbance_bounds
from ..observers.gains import check_gains, discrete_gains
from ..validate import NONNEGATIVE, POSITIVE, UDOT_MAX, below_nyquist, real
from .checks import rho_interval
from .ellipsoid import copy_error_bound, jump_mismatch
from .results import RobustCertificate
from .robust_cover import cover_inputs, input_step_bound, plant_peaks, tracking_parts
from .robust_ellipsoid import Ellipsoids, contraction

__all__ = ["RobustCertificate", "certify_robust"]

#: Exogenous entries of one step: reference terms, x3, j, dh, n, d, r1, r2 (:func:`_step`).
_NS = 12
#: Bounds below this share of the loop's signal size (sup |x_d| + h_max) are stated as it.
ROUNDING = 1e-12


@dataclass(frozen=True)
class _Loop:
    Fm: np.ndarray
    gm: np.ndarray
    K: np.ndarray
    Kx: np.ndarray
    Kr: np.ndarray
    ki: float
    dt: float
    integral: bool
    delay: bool

    @property
    def n(self) -> int:
        return 5 + int(self.integral) + int(self.delay)


def _applied(lp: _Loop, z: np.ndarray, s: np.ndarray) -> float:
    """The input applied over sample ``k`` (linear in ``z`` and ``s``; see :func:`_step`)."""
    d, e = z[0:2], z[2:5]
    q = z[5] if lp.integral else 0.0
    uref, x3, n = s[4], s[5], s[8]
    ep = e - lp.K * e[0] + lp.K * n
    Kx = lp.Kx
    ut = z[-1] if lp.delay else lp.ki * q + Kx[0] * d[0] + Kx[1] * d[1] + Kx @ ep
    return float(uref + Kx[2] * x3 + ut)


def _step(lp: _Loop, Fv, gv, rho: float, z: np.ndarray, s: np.ndarray) -> np.ndarray:
    """One sample of the error system (linear in ``z`` and ``s``; see the module doc).

    ``s = (x_d, x_d', x_d(k+1), x_d'(k+1), uref, x3, j, dh, n, d, r1, r2)`` with
    ``uref = ff + Kx1 x_d + Kx2 x_d'``, ``d`` the input disturbance held over the
    sample and ``r`` its within-sample remainder (both act on the plant only).
    """
    d, e = z[0:2], z[2:5]
    q = z[5] if lp.integral else 0.0
    xd, vd, xd1, vd1, uref, x3, j, dh, n = s[:9]
    ep = e - lp.K * e[0] + lp.K * n
    Kx = lp.Kx
    u = _applied(lp, z, s)
    xt = np.array([xd + d[0], vd + d[1], x3 + j])
    dn = Fv[:2] @ xt + gv[:2] * u - np.array([xd1, vd1])
    en = lp.Fm @ np.array([ep[0], ep[1], rho * ep[2] + dh]) + (lp.Fm - Fv) @ xt + (lp.gm - gv) * u
    if np.any(s[9:]):  # the plant's extra step g_true d + r; the observer does not see it
        pd = gv[:2] * s[9] + s[10:12]
        dn = dn + pd
        en = en - np.array([pd[0], pd[1], 0.0])
    out = [dn, en]
    if lp.integral:
        inc = dn[0] + en[0] if lp.delay else d[0] + ep[0]
        out.append(np.array([q + lp.dt * inc]))
    if lp.delay:
        out.append(np.array([lp.ki * q + Kx[0] * dn[0] + Kx[1] * dn[1] + Kx @ en]))
    return np.concatenate(out)


def _matrices(lp: _Loop, Fv, gv, rho: float) -> tuple[np.ndarray, np.ndarray]:
    n = lp.n
    A = np.column_stack([_step(lp, Fv, gv, rho, z, np.zeros(9)) for z in np.eye(n)])
    B = np.column_stack([_step(lp, Fv, gv, rho, np.zeros(n), s) for s in np.eye(_NS)])
    return A, B


def _hyst_bounds(model: BoucWenParams, tp: BoucWenParams, du: float) -> tuple[float, float, float]:
    hv = tp.bounded_class().h_max
    j = hysteresis_slope_range(tp)[1] * du
    return hv, j, jump_mismatch(model, tp, du)


def certify_robust(
    loop: ClosedLoop,
    *,
    uncertainty: UncertaintyBox,
    udot_max: float,
    reference: Reference,
    noise_max: float = 0.0,
    a: float | None = None,
    interior_samples: int = 16,
    seed: int = 0,
    disturbance: DisturbanceBound | None = None,
    uddot_max: float | None = None,
) -> RobustCertificate:
    """Certify a sampled PHSO (or PHDO) tracking loop over every plant in an uncertainty box.

    Parameters
    ----------
    loop : ClosedLoop
        The loop certified: its ``model`` (observer and law), its observer (``"phso"``,
        or ``"phdo"`` with ``l3 = 0``; continuous gains, pole-matched to ``K`` as the
        observer runs them), its discrete eq. (12) law
        (:class:`~bwdesign.control.controllers.DiscreteTrackingController` at the
        loop's ``dt``, built on ``model``, with or without integral action, without
        the hysteresis jump), its ``dt`` and its one-sample delay (compensated, as the
        digital tuning). The certificate covers the loop *without* its input limits
        and estimate clipping: a saturating loop is certified only while it does not
        saturate.
    uncertainty : UncertaintyBox
        The box of true plants: finite, every corner a bounded plant
        (:meth:`UncertaintyBox.check`; ``ParameterError`` otherwise).
    udot_max : float
        Input-rate envelope (V/s) the certificate assumes: ``|du| <= udot_max dt``.
    reference : Reference
        The reference tracked. Its terms are covered at every time ``t >= 0`` (every
        phase of a periodic reference; the whole of a settling one, up to
        :attr:`~bwdesign.model.references.Reference.settles_at`), by
        :func:`bwdesign.model.reference_cover.sup_abs`: an upper bound, not a window's
        maximum. A reference that states neither a period nor a settling time, or not
        its breakpoints and derivative bounds, is refused (``InputError``).
    noise_max : float
        Sensor noise bound ``|n| <= noise_max`` (length unit).
    a : float, optional
        Contraction per sample in ``(0, 1)``; default: where the peak-to-peak bounds
        apply (they give the certified bounds), the fastest feasible contraction of a
        grid on ``log(1 - a)``; otherwise searched for the smallest ellipsoid bound.
    interior_samples : int
        Seeded interior points of the box where the same ``P`` is re-checked.
    seed : int
    disturbance : DisturbanceBound, optional
        A slowly varying input-equivalent disturbance ``d`` on every plant of the box
        (``x2' = ... + a3 (u + d)``, ``|d| <= input_max``, ``|d'| <= rate_max``; the
        stage's ``[uncertainty.disturbance]``). ``None`` (or both bounds 0): none.
    uddot_max : float, optional
        A second envelope the certificate assumes, on the input's second differences:
        ``|u_{k+1} - 2 u_k + u_{k-1}| <= uddot_max dt^2`` (V/s^2). With it the plant's
        hysteresis jump is bounded by
        :func:`~bwdesign.model.plant.hysteresis_jump_bound` (the slope is high only just
        after the input turns, where its steps are small) instead of ``hi |du|``; the
        verdict states it as an assumption. ``None``: no such assumption.

    Returns
    -------
    RobustCertificate

    Raises
    ------
    InputError
        A loop this certificate does not cover (another observer, a continuous or
        foreign law, an uncompensated delay, the hysteresis jump), a bad reference or
        envelope.

    Notes
    -----
    The PHDO with ``l3 = 0`` (the digital tuning's
    :func:`~bwdesign.observers.gains.disturbance_gains_from`) uses the lumped
    ``x3hat + dhat``. Its hysteresis copy runs on the model alone, so
    ``|x3hat - x3| <= h_max(model) + h_max(plant)`` for every input, and the lumped
    error ``(e1, e2, e3 + ed)`` is the PHSO's error system with ``rho = 1`` driven by
    the extra input ``(rho - 1) e3``, bounded by ``(1 - rho_lo)(h_max(model) +
    h_max(plant))``; that is what is certified, and ``x3_estimation_bound`` bounds the
    lumped ``|x3hat + dhat - x3|``.
    """
    lp, observer = _loop(loop)
    params = loop.model
    udot_max = real(udot_max, "udot_max (V/s)", within=UDOT_MAX)
    noise_max = real(noise_max, "noise_max", within=NONNEGATIVE)
    if not isinstance(uncertainty, UncertaintyBox):
        raise InputError("uncertainty must be an UncertaintyBox")
    if not isinstance(reference, Reference):
        raise InputError(f"reference must be a bwdesign Reference, got {reference!r}")
    below_nyquist(reference, lp.dt)
    require_coverable(reference, lp.dt)
    if uddot_max is not None:
        uddot_max = real(uddot_max, "uddot_max (V/s^2)", within=POSITIVE)
    uncertainty.check(params)  # every corner (so every plant in the box) bounded
    args = (loop, uncertainty, udot_max, reference, noise_max, a, interior_samples, seed)
    rest = (disturbance, uddot_max)
    computed = (lp, observer)  # the loop's matrices, built once: not part of the key
    return _CERTIFIED.get((*args, *rest), lambda: _certify(*args, *rest, *computed))


#: :func:`certify_robust`'s certificates kept by their exact (checked) arguments, in this
#: process (a pure function of them; the report's parts and the rate search ask again).
_CERTIFIED: Memo[RobustCertificate] = Memo(16)


def _certify(
    loop: ClosedLoop,
    uncertainty: UncertaintyBox,
    udot_max: float,
    reference: Reference,
    noise_max: float,
    a: float | None,
    interior_samples: int,
    seed: int,
    disturbance: DisturbanceBound | None,
    uddot_max: float | None,
    lp: _Loop,
    observer: str,
) -> RobustCertificate:
    """:func:`certify_robust` of checked arguments (``lp``, ``observer``: :func:`_loop`'s)."""
    params = loop.model
    vertices = uncertainty.vertices(params)
    rng = np.random.default_rng(seed)
    # a box of zero width is the nominal plant alone: nothing inside to sample
    varying = any(lo != hi for lo, hi in uncertainty.bounds(params).values())
    interior = uncertainty.sample(params, rng, int(interior_samples)) if varying else []
    st = _setup(params, lp, observer, udot_max, disturbance_bounds(disturbance))
    size = float(sup_abs(reference, lp.dt, np.eye(9)[:1])[0]) + params.bounded_class().h_max
    # the plant's jump over the box (every constant it uses is extreme at a corner)
    second = None if uddot_max is None else uddot_max * lp.dt**2
    jump = hysteresis_jump_bound(vertices, st.du, second)
    change = (
        math.inf if second is None else hysteresis_jump_change_bound(vertices, st.du, second, jump)
    )
    st = replace(st, scale=size, uddot_max=uddot_max, jump=jump, jump_diff=change)
    data = [_plant_data(st, tp) for tp in vertices + interior]
    # both covers of the reference (.robust_cover): the smaller certified bound
    # the ellipsoid on the per-sample cover first (the exact one if that fails); the
    # peak-to-peak bounds of every cover, the smallest kept (_conclude), and with the
    # jump as a slow input too where its change is bounded (neither is smaller everywhere)
    kept: dict[bool, Any] = {}
    covers = _covers(st, reference, data, noise_max, kept)
    every = list(covers)
    if math.isfinite(change):
        slow = replace(st, jump_change=change)
        every += _covers(slow, reference, [_plant_data(slow, tp) for tp in vertices + interior],
                         noise_max, kept)  # fmt: skip
    for covered, dd in covers[::-1]:
        rc = _certify_with(st, dd, len(vertices), covered, a, noise_max, every)
        if rc.holds:
            break
    return rc


def _covers(st: _Setup, reference: Reference, data: list[dict], noise_max: float, kept: dict):
    """The covers of the reference's terms (:mod:`.robust_cover`): exact where it applies,
    and per sample; each with its own copy of the plants' data. ``kept``: the reference's
    part, shared by the jump's two treatments (the same plants' rows)."""
    out = []
    for exact in (True, False):
        dd = [dict(d) for d in data]
        covered = cover_inputs(st, reference, dd, noise_max, exact, kept)
        if covered is not None:
            out.append((covered, dd))
    return out


def _certify_with(st: _Setup, data: list[dict], n_v: int, covered, a, noise_max: float, covers):
    """The common ellipsoid for one cover of the inputs, checked and concluded."""
    hb, W, input_bounds = covered
    nominal = _plant_data(st, st.params)["blocks"][0]
    ell = Ellipsoids.build(st, data[:n_v], data[n_v:], W, nominal)
    base = {
        "n_vertices": n_v,
        "n_interior": len(data) - n_v,
        "input_bounds": input_bounds,
        "noise_max": noise_max,
    }
    spec = ell.spectral_radius()
    rho = f"rho in [{st.rho_lo:.6g}, {st.rho_hi:.6g}]"
    if spec >= 1:
        why = f"the loop is unstable at {ell.hardest()} >= 1 at {rho}"
        return _not_certified(base, why, math.nan, {"spectral_radius": spec})
    # every bound the peak-to-peak method gives is taken where smaller (_conclude); where it
    # gives one, the ellipsoid is needed for the common Lyapunov function (the decay and
    # the certificate over the box), not for its own bound: the fastest feasible contraction
    # of the grid does, not the search for the one with the smallest ellipsoid bound
    peaks = [(cov, dd, l1) for cov, dd in covers if (l1 := plant_peaks(st, dd, cov[1])) is not None]
    quick = a is None and bool(peaks)
    sol, av = contraction(ell, a, spec, st.statics[0], first=quick)
    sol = ell.firm(sol, av, st.statics[0], st, data)  # a larger margin if the check fails
    if (
        quick
        and sol is not None
        and sol.ok
        and not all(m.passed for m in ell.check(sol, av, st, data)[0])
    ):
        sol, av = contraction(ell, a, spec, st.statics[0])  # the full search after all
        sol = ell.firm(sol, av, st.statics[0], st, data)
    if sol is None or not sol.ok:
        status = sol.status if sol is not None else "infeasible for every contraction tried"
        why = (
            f"no common Lyapunov function over the {n_v} corners and {rho} ({status}); the "
            f"hardest plant is the {ell.hardest()}"
        )
        details = {"spectral_radius": spec, "attempts": list(sol.attempts) if sol else []}
        return _not_certified(base, why, av, details, sol.solver if sol is not None else "")
    return _conclude(st, ell, data, (sol, av), hb, noise_max, spec, st.lp.dt, base, peaks)


def _not_certified(
    base: dict[str, Any], why: str, a: float, details: dict[str, Any], solver: str = ""
) -> RobustCertificate:
    return RobustCertificate(
        holds=False,
        status=f"not certified: {why}",
        decay=None,
        tracking_bound=None,
        estimation_bound=None,
        x3_estimation_bound=None,
        a=a,
        solver=solver,
        details=details,
        **base,
    )


def _loop(loop: ClosedLoop) -> tuple[_Loop, str]:
    """The certified loop's matrices: ZOH model, discrete observer gain, eq. (12) law."""
    if not isinstance(loop, ClosedLoop):
        raise InputError(f"loop must be a ClosedLoop, got {type(loop).__name__}")
    loop.require_observer("the robust loop certificate")
    params, obs, ctrl = loop.model, loop.observer, loop.controller
    require_bounded(params)
    if not obs.hysteresis_model:
        raise InputError(
            f"the robust loop certificate covers the PHSO and the PHDO, not {obs.kind!r}"
        )
    if not isinstance(ctrl, DiscreteTrackingController) or loop.dt is None:
        raise InputError(
            "the robust loop certificate needs the discrete eq. (12) law "
            "(DiscreteTrackingController) at the loop's dt"
        )
    if ctrl.params != params:
        raise InputError("the loop's law must be built on the loop's model")
    if ctrl.hysteresis_jump:
        raise InputError("the robust loop certificate does not cover the hysteresis jump")
    if loop.delay and not loop.compensate_delay:
        raise InputError(
            "the robust loop certificate covers the one-sample delay compensated only "
            "(compensate_delay=True)"
        )
    if obs.four_state:
        l4 = np.asarray(obs.gains, float)
        if l4[2] != 0:
            raise InputError(
                "the robust loop certificate of the PHDO needs l3 = 0 (the hysteresis copy on "
                f"the model alone, as the digital tuning splits it), got l3 = {l4[2]:g}"
            )
        l = check_gains(params, (l4[0], l4[1], l4[2] + l4[3]))
    else:
        l = check_gains(params, obs.gains)
    Kx, Kr = ctrl.linear_gains()
    zm = discretize(params, loop.dt)
    lp = _Loop(
        Fm=np.asarray(zm.F),
        gm=np.asarray(zm.g),
        K=discrete_gains(params, l, loop.dt),
        Kx=np.asarray(Kx, float),
        Kr=np.asarray(Kr, float),
        ki=float(ctrl.ki),
        dt=float(loop.dt),
        integral=ctrl.integral_rate is not None,
        delay=loop.delay,
    )
    return lp, obs.kind


@dataclass(frozen=True)
class _Setup:
    """What every plant of the box shares: the loop, the ``rho`` ends and the output rows."""

    params: BoucWenParams
    lp: _Loop
    observer: str
    udot_max: float
    du: float
    rho_lo: float
    rho_hi: float
    rhos: tuple[float, ...]
    M: np.ndarray
    dM: np.ndarray
    statics: tuple[np.ndarray, np.ndarray, np.ndarray]
    cu: np.ndarray
    su: np.ndarray
    #: the input disturbance's bounds ``(input_max, rate_max)``, (0, 0) for none
    dist: tuple[float, float] = (0.0, 0.0)
    #: the size of the loop's signals, ``sup |x_d| + h_max`` (length unit)
    scale: float = 0.0
    #: the input's second-difference envelope assumed (V/s^2), None: none
    uddot_max: float | None = None
    #: the plant's jump over one sample, over the box (``model.plant.hysteresis_jump_bound``)
    jump: float = math.inf
    #: the change of that jump from one sample to the next (with ``uddot_max``: the jump is
    #: then a slow input, module doc); inf: the jump is a fast input
    jump_change: float = math.inf
    #: that change's bound beside a fast jump (the peak-to-peak bounds then take both
    #: constraints, :func:`.peak.l1_bounded_change`); inf: none assumed
    jump_diff: float = math.inf

    @property
    def n(self) -> int:
        return self.lp.n


def _setup(
    params: BoucWenParams, lp: _Loop, observer: str, udot_max: float, dist: tuple[float, float]
) -> _Setup:
    dt = lp.dt
    rho_lo, rho_hi = rho_interval(params, udot_max, dt)
    # the PHDO's lumped error: rho = 1 in the loop, (rho - 1) e3 an input beside dh
    rhos = (rho_lo, rho_hi) if observer == "phso" else (1.0,)
    # the reference terms as functionals of sigma(t) = (x_d, x_d', x_d'') at t, t + dt,
    # t + 2 dt (model.reference_cover): R(t) = M sigma(t) = (x_d, x_d', x_d(t+dt),
    # x_d'(t+dt), uref) and R at the next sample = M1 sigma(t); their supremum over every
    # t >= 0 is bounded once for all plants (_cover)
    Kx, Kr = lp.Kx, lp.Kr
    kx, kd = Kr[0] + Kx[0], Kr[1] + Kx[1]
    M = np.zeros((5, 9))
    M[[0, 1, 2, 3], [0, 1, 3, 4]] = 1.0
    M[4, :3] = (kx, kd, Kr[2])
    M1 = np.roll(M, 3, axis=1)
    M1[:, :3] = 0.0
    n = lp.n
    e = np.eye(n)
    statics = (e[0], (1 - lp.K[0]) * e[2], e[4] - lp.K[2] * e[2])  # tracking, x1hat, x3hat
    # the applied input u_k = cu' z_k + su' s_k, for the bound on its steps
    cu = np.array([_applied(lp, z, np.zeros(9)) for z in np.eye(n)])
    su = np.array([_applied(lp, np.zeros(n), v) for v in np.eye(9)])
    return _Setup(
        params, lp, observer, udot_max, udot_max * dt, rho_lo, rho_hi, rhos, M, M1 - M, statics,
        cu, su, dist,
    )  # fmt: skip


def _plant_data(st: _Setup, tp: BoucWenParams) -> dict[str, Any]:
    """Per plant: its blocks (A, B~) per rho end, channel bounds and the reference rows."""
    lp, n, rhos, M, dM = st.lp, st.n, st.rhos, st.M, st.dM
    zt = discretize(tp, lp.dt)
    Fv, gv = np.asarray(zt.F), np.asarray(zt.g)
    mats = [_matrices(lp, Fv, gv, r) for r in rhos]
    Bref, bx3 = mats[0][1][:, :5], mats[0][1][:, 5]  # rho acts on neither
    hv, j, dh = _hyst_bounds(st.params, tp, st.du)
    j = min(j, st.jump)
    copy_error = copy_error_bound(st.params, tp)
    if st.observer == "phdo":  # the step of (rho - 1) e3 + dh, |e3| <= the copy's error
        dh += (1 - st.rho_lo) * copy_error
    # quasi-static split (module doc): z = z~ + G^-1 w_slow, G = I - A(rho_c)
    G = np.eye(n) - np.mean([A for A, _ in mats], axis=0)
    GiB = np.linalg.solve(G, Bref)  # w_slow's reference part: G^-1 Bref M sigma
    Gib = np.linalg.solve(G, bx3)
    Gid = np.linalg.solve(G, mats[0][1][:, 9])  # the held disturbance's quasi-static part
    rows = [GiB @ dM]  # the increments of the reference terms, per state
    if len(rhos) == 2:
        E = (mats[1][0] - mats[0][0]) / (rhos[1] - rhos[0])
        rows.append(E @ GiB @ M)  # the rho coupling of the quasi-static part
    rows += [np.array([c @ GiB @ M for c in st.statics])]
    for A, _ in mats:  # the input steps' reference part, per rho end (input_step_bound)
        v = (A - np.eye(n)).T @ st.cu
        rows.append(((v @ GiB + st.cu @ Bref) @ M + st.su[:5] @ dM)[None, :])
    # the jump: a fast input, or (with the second-difference envelope) a slow one whose
    # quasi-static part G^-1 b_e j leaves its increments as the input (module doc)
    b_e = mats[0][1][:, 6] - Gib  # rho acts on neither x3 nor j
    slow = math.isfinite(st.jump_change)
    Gie = np.linalg.solve(G, b_e) if slow else np.zeros(n)
    # fast inputs (j or its change, dh, n), the disturbance's increment and remainder
    blocks = [
        (A, np.column_stack([np.eye(n), -Gie if slow else b_e, B[:, 7:9], -Gid, B[:, 10:12]]))
        for A, B in mats
    ]
    E_b = E if len(rhos) == 2 else None
    return {
        "blocks": blocks,
        "hyst": (hv, j, dh),
        "copy_error": copy_error,
        "Ac": np.eye(n) - G,  # the reference's own response runs at the middle rho
        "Bref": Bref,
        "mats": mats,
        "Gib": Gib,
        "Gid": Gid,
        "Gie": Gie,
        # the bound of the jump's channel: the jump, or its change (at most twice the jump)
        "jchan": min(st.jump_change, 2 * j) if slow else j,
        # the fast jump's change from one sample to the next (inf: not bounded)
        "jdiff": math.inf if slow else st.jump_diff,
        "a3": abs(tp.a3),
        "E": E_b,
        "rows": np.vstack(rows),
        "plant": tp,
    }


def _rate_clause(step: float, st: _Setup, dt: float, unit: str) -> str:
    """The verdict's input-rate clause: proved (the certificate's own bound on the input
    steps keeps the envelope it assumed, so the assumption holds once the loop is in
    its steady set) or stated as the condition it is; the second-difference envelope,
    when one is assumed, is always stated as an assumption."""
    udot_max = st.udot_max
    if step <= udot_max * dt:
        out = (
            f"and the loop's input keeps |u'| <= {udot_max:.4g} {unit}/s (proved: the "
            f"certificate bounds it by {step / dt:.4g} {unit}/s in steady state, a margin of "
            f"{udot_max * dt / step:.4g}x)"
        )
    else:
        out = (
            f"if the loop's input keeps |u'| <= {udot_max:.4g} {unit}/s (assumed, not proved: "
            f"this certificate bounds the loop's own input rate only by {step / dt:.4g} "
            f"{unit}/s)"
        )
    if st.uddot_max is not None:
        out += (
            f"{' and if' if step <= udot_max * dt else ' and'} its second differences keep "
            f"|u_(k+1) - 2 u_k + u_(k-1)| <= dt^2 x {st.uddot_max:.4g} {unit}/s^2 (assumed, "
            "not proved)"
        )
    return out


def _status(
    st: _Setup, base: dict[str, Any], bounds: list, decay: float, step: float, dt: float
) -> str:
    """The status line of a certificate that holds: its plants, bounds, rate and disturbance."""
    unit = st.params.input_unit
    status = (
        (
            f"certified over {base['n_vertices']} corners (+{base['n_interior']} interior points)"
            if base["n_vertices"] > 1 or base["n_interior"]
            else "certified for the nominal plant"
        )
        + f": steady |x1 - x_d| <= {bounds[0]:.4g}, |x1hat - x1| <= {bounds[1]:.4g}, "
        f"|x3hat - x3| <= {bounds[2]:.4g} (length unit), convergence >= {decay:.4g} 1/s, "
        + _rate_clause(step, st, dt, unit)
    )
    if st.dist != (0.0, 0.0):
        status += (
            f", and an input disturbance |d| <= {st.dist[0]:.4g} {unit}, |d'| <= "
            f"{st.dist[1]:.4g} {unit}/s on the plant"
        )
    return status


def _conclude(
    st: _Setup,
    ell: Ellipsoids,
    data: list[dict],
    solved: tuple[Any, float],
    hb: np.ndarray,
    noise_max: float,
    spec: float,
    dt: float,
    base: dict[str, Any],
    peaks: list,
) -> RobustCertificate:
    """The certificate of a solved ellipsoid: outside check, bounds, decay and status.

    ``peaks``: ``(cover, data, per-plant peak-to-peak bounds)`` of every cover that has them.
    """
    sol, av = solved
    lp = st.lp
    margins, peak, dyn = ell.check(sol, av, st, data)
    holds = all(m.passed for m in margins)
    step = input_step_bound(st, data, lambda v, _: dyn(v), hb, noise_max) if holds else None
    bounds = [peak(0), None, None]
    # the estimation bounds: their own objective at the same contraction, where no
    # peak-to-peak bound is computed (where one is, it was the smaller on every bundled
    # stage and +-5 % box: 14 rows, all equal with and without these two solves)
    for i in (1, 2) if not peaks else ():
        s2 = ell.attempt(av, st.statics[i])
        if s2.ok:
            m2, pk, _ = ell.check(s2, av, st, data)
            if all(m.passed for m in m2):
                bounds[i] = pk(i)
        if bounds[i] is None and holds:
            bounds[i] = peak(i)
    method, slow_jump, jump_how = "ellipsoid", None, "fast"
    half = (st.rhos[-1] - st.rhos[0]) / 2
    parts = None  # the tracking bound's: (its cover's W, the plant's data) where peak-to-peak
    for (hb2, W, _), dd, l1 in peaks if holds else ():
        # the per-plant peak-to-peak bounds (.peak), where smaller
        for i in range(3):
            per = [float(p[i]) + float(d["static"][i]) for p, d in zip(l1, dd, strict=True)]
            b = max(per)
            if bounds[i] is None or b < bounds[i]:
                bounds[i], method = b, "peak-to-peak"
                if i == 0:
                    parts = (W, dd[int(np.argmax(per))])
                if i == 0 and np.any(dd[0]["Gie"]):  # the jump a slow input: its change
                    slow_jump, jump_how = max(d["jchan"] for d in dd), "slow"
                elif i == 0 and math.isfinite(dd[0]["jdiff"]):  # fast, its change bounded
                    slow_jump, jump_how = dd[0]["jdiff"], "fast, change bounded"
                elif i == 0:
                    slow_jump, jump_how = None, "fast"
        dyn1 = lambda v, j, l1=l1: l1[j][3] + half * l1[j][-1]  # noqa: E731
        step = min(step, input_step_bound(st, dd, dyn1, hb2, noise_max))
    if bounds[1] is not None:
        bounds[1] += abs(lp.K[0]) * noise_max
    if bounds[2] is not None:
        bounds[2] += abs(lp.K[2]) * noise_max
    # no bound finer than double precision resolves: the loop's signals are of the size
    # of the reference and the hysteresis, computed to a few ulps of that
    floor = ROUNDING * st.scale
    bounds = [None if b is None else max(b, floor) for b in bounds]
    decay = -math.log(av) / (2 * dt)
    worst = max(margins, key=lambda m: m.value - m.limit)
    udot_max = st.udot_max
    status = (
        _status(st, base, bounds, decay, step, dt)
        if holds
        else (
            f"not certified: the solver's P failed the outside check ({worst.name}: "
            f"min eig {-worst.value:.3g})"
        )
    )
    return RobustCertificate(
        holds=holds,
        status=status,
        decay=decay if holds else None,
        tracking_bound=bounds[0] if holds else None,
        estimation_bound=bounds[1] if holds else None,
        x3_estimation_bound=bounds[2] if holds else None,
        a=av,
        margins=tuple(margins),
        solver=sol.solver,
        details={
            "spectral_radius": spec,
            "rho_interval": [st.rho_lo, st.rho_hi],
            "observer": st.observer,
            "udot_max": udot_max,
            "dt": dt,
            "input_step_bound": step,
            "bound_method": method,
            "rounding_floor": floor,
            # the LMI blocks' margin (>= margin I) of the kept solution (.robust_ellipsoid.EPS)
            "lmi_margin": ell.margin,
            # the envelope shown by the certificate itself (a fixed point), or assumed
            "rate_proved": bool(holds and step is not None and step <= udot_max * dt),
            "rate_margin": (udot_max * dt / step) if holds and step else None,
            # the second-difference envelope assumed (None: none) and the jump bound it gives
            "uddot_max": st.uddot_max,
            "jump_bound": float(hb[1]),
            # the tracking bound's: the jump as a slow input (its change the input), a fast
            # one whose change bound was given to the peak-to-peak bounds too (which use it
            # only where it can tighten them, .peak.l1_bounded_change), or a fast one
            "jump_input": jump_how,
            "jump_change_bound": slow_jump,
            # what each input adds to the tracking bound at the plant attaining it
            # (peak-to-peak; None for the ellipsoid's, which does not split)
            "tracking_bound_parts": tracking_parts(st, parts[1], parts[0]) if parts else None,
        },
        **base,
    )
