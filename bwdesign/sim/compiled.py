"""The batched loop's sample step, compiled (numba): scenario by scenario, no array overhead.

:func:`bwdesign.sim.simulate_batch` ran :mod:`bwdesign.sim.kernel`'s step on numpy arrays,
one array operation per term and time step: for the few dozen scenarios of a box's corners
(the report, the falsifier) the arrays are short and the interpreter's overhead per
operation is the whole cost (about 25 us per time step, issue 28). The two functions here
are that step written out once more as scalar code, compiled by numba and run scenario
after scenario (each scenario's state and sums in local scalars; the observer loop two
scenarios side by side, so the processor overlaps their independent sample chains):
:func:`observer_batch` (:func:`~bwdesign.sim.kernel.correct` and
:func:`~bwdesign.sim.kernel.advance`) and :func:`baseline_batch`
(:func:`~bwdesign.sim.kernel.advance_baseline`); :func:`observer_trace` runs the observer
loop's step (the same inline helpers) for one scenario and keeps its record, for
:func:`bwdesign.sim.simulate`'s fast path. Each does the scalar loop's float
operations in the same order, with the same closed-form hysteresis jump
(:func:`bwdesign.model.plant.hysteresis_increment`; numba calls the same libm
``expm1`` and ``log1p`` as Python's ``math``), so every scenario's metrics equal
:func:`bwdesign.sim.simulate`'s to the bit (tested, noise, delay and limits included).

The arguments are plain float64 arrays and flags (:mod:`bwdesign.sim.batch` packs them);
inside the step only scalars are passed (an array handed to a function costs two atomic
reference counts per call, which were 40 % of the step). :func:`scaled_normals` draws the
noise with numba's ``Generator``: numpy's bit generator and ziggurat, numpy's numbers.
A scenario that leaves the divergence limits stops there: its step index and state are
returned for the message, its metrics are not used. The compiled code is cached beside
this file (``cache=True``), so only the first run on a machine pays the compilation.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "observer_batch",
    "observer_trace",
    "baseline_batch",
    "observer_drawn",
    "baseline_drawn",
    "hysteresis_jump",
    "scaled_normals",
    "noise_rows",
]


@njit(cache=True, inline="always")
def _branch(h, w, alpha, c):
    x = c * w
    e = math.expm1(-x)
    if not abs(x) >= 1e-8:  # NaN too: alpha / c below only where c != 0
        frac = 1.0 - x / 2.0 + x * x / 6.0
        return h + (h * e + alpha * w * frac)
    return h + e * (h - alpha / c)  # alpha / c is loop-invariant: computed once a run


@njit(cache=True, inline="always")
def _inside_first_branch(w, cm, arg):
    """The jump ends before the zero crossing, decided without ``log1p`` where it is clear
    (the test :func:`bwdesign.model.plant.hysteresis_increment` makes, same operations)."""
    if cm > 0.0:
        num, den = arg, 1.0 + arg
    else:
        num, den = -arg, 1.0
    return num >= 1e-6 * den and w * abs(cm) * den <= 0.5 * num


@njit(cache=True, inline="always")
def hysteresis_jump(alpha, beta, gamma, h, u0, u1):
    """:func:`bwdesign.model.plant.hysteresis_increment`, compiled (same operations)."""
    du = u1 - u0
    if du == 0.0:
        return h
    s = 1.0 if du > 0.0 else -1.0
    g = s * h
    w = abs(du)
    if g < 0.0:
        cm = beta - gamma
        if cm == 0.0:
            wz = -g / alpha
        else:
            arg = -cm * g / alpha
            if _inside_first_branch(w, cm, arg):
                return s * _branch(g, w, alpha, cm)
            wz = math.log1p(arg) / cm if arg > -1.0 else math.inf
        if w <= wz:
            return s * _branch(g, w, alpha, cm)
        g = 0.0
        w = w - wz
    return s * _branch(g, w, alpha, beta + gamma)


@njit(cache=True, inline="always")
def _clip(v, lo, hi):
    # min(max(v, lo), hi) as the scalar loop (NaN stays NaN)
    if lo > v:
        v = lo
    if v > hi:
        v = hi
    return v


@njit(cache=True, inline="always")
def _law(law, lim, ff, xd, a, b, h, q):
    """:func:`bwdesign.sim.kernel._law` without the jump: ``(v, q)``.

    ``law`` = kx1, kx2, kx3, ki, cdt, ulo, uhi, integral, clip and ``lim`` the estimate
    limits, as tuples; ``ff``, ``xd`` this sample's reference terms. Scalars only: an
    array passed to a function inside the loop costs a reference count up and down per
    call (atomic operations that were 40 % of the step, issue 28).
    """
    if law[8] != 0.0:
        a = _clip(a, lim[0], lim[1])
        b = _clip(b, lim[2], lim[3])
        h = _clip(h, lim[4], lim[5])
    f = ff + law[3] * q
    v = f + law[0] * a + law[1] * b + law[2] * h
    if law[7] != 0.0:
        q = q + law[4] * (a - xd)
    return _clip(v, law[5], law[6]), q


def observer_batch(plant, consts, ref, noise, dist, out):
    """Run the observer loop for every scenario (rows of ``plant``).

    Parameters (float64 unless said)
    ----------
    plant : (N, 12)
        p11, p12, p13, p21, p22, p23, g1, g2, alpha, beta, gamma, velocity limit.
    consts : tuple of arrays
        ``model`` (11: m11, m12, m13, m21, m22, m23, mg1, mg2, alpha, beta, gamma of the
        model), ``gains`` (4: K1..K4 of the sampled observer, K4 = 0 without the
        disturbance state), ``law`` (9) and ``lim`` (6) as :func:`_law`, ``flags`` (6: four,
        phso, delay, compensate, divergence limit, has noise), ``start`` (7: x1, x2, x3,
        xhat1, xhat2, xhat3, u_prev).
    ref : (3, n + 1)
        ff (the law's reference term), x_d, the in-window mask (1.0 inside).
    noise : (N, n)
        Sensor noise (read only with the noise flag).
    dist : (R, n)
        Input disturbance per sample: no row (none), one row (common) or one per scenario.
    out : (N, 21)
        Written: sum_abs, sum_sq, max_abs, est_sq x3, est_max x3, du_max, alive, the step
        of the divergence, the state there (x1, x2, x3, xhat1, xhat2, xhat_lumped, u_a),
        the number of samples whose applied input is at an input limit, d2u_max (the
        largest ``|u_k - 2 u_(k-1) + u_(k-2)|`` of the applied input in the window).
    """
    _observer_batch(plant, *consts, ref, noise, dist, out)


@njit(cache=True, inline="always")
def _plant_row(plant, i):
    """Row ``i`` of ``plant`` as a tuple (its entries stay in registers over the run) and
    its velocity limit."""
    r = plant[i]
    return (r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8], r[9], r[10]), r[11]


@njit(cache=True, inline="always")
def _plant_step(p, x1, x2, x3, uprev, applied, ud):
    """The true plant's jump and ZOH step (``p``: a row of ``plant`` as a tuple), as
    :func:`bwdesign.sim.kernel.advance`: the linear part sees ``ud``, the hysteresis ``u``."""
    hh = hysteresis_jump(p[8], p[9], p[10], x3, uprev, applied)
    nx1 = p[0] * x1 + p[1] * x2 + p[2] * hh + p[6] * ud
    nx2 = p[3] * x1 + p[4] * x2 + p[5] * hh + p[7] * ud
    return nx1, nx2, hh


@njit(cache=True, inline="always")
def _stop(out, i, k, x1, x2, x3, h1, h2, hw, ua):
    """Mark scenario ``i`` diverged at step ``k``, with its state there."""
    out[i, 10] = 0.0
    out[i, 11] = k
    out[i, 12], out[i, 13], out[i, 14] = x1, x2, x3
    out[i, 15], out[i, 16], out[i, 17], out[i, 18] = h1, h2, hw, ua


@njit(cache=True, inline="always")
def _loop_constants(model, gains, law, lim, flags, rows):
    """The observer loop's constants as tuples (their entries stay in registers over the
    run): the switches (four, phso, delay, compensate, a disturbance given), the gains, the
    model, the law and the estimate limits (:func:`observer_batch`'s ``consts``)."""
    sw = (flags[0] != 0.0, flags[1] != 0.0, flags[2] != 0.0, flags[3] != 0.0, rows > 0)
    K = (gains[0], gains[1], gains[2], gains[3])
    m = (model[0], model[1], model[2], model[3], model[4], model[5], model[6], model[7],
         model[8], model[9], model[10])  # fmt: skip
    lw = (law[0], law[1], law[2], law[3], law[4], law[5], law[6], law[7], law[8])
    lm = (lim[0], lim[1], lim[2], lim[3], lim[4], lim[5])
    return sw, K, m, lw, lm


@njit(cache=True, inline="always")
def _correct(K, four, z, h1, h2, h3, hd):
    """:func:`bwdesign.sim.kernel.correct`: the posterior ``(h1, h2, h3, hd, hw)`` after ``z``."""
    r = z - h1
    h1 = h1 + K[0] * r
    h2 = h2 + K[1] * r
    h3 = h3 + K[2] * r
    if four:
        hd = hd + K[3] * r
        hw = h3 + hd
    else:
        hw = h3
    return h1, h2, h3, hd, hw


@njit(cache=True, inline="always")
def _advance(p, m, lw, lm, sw, x, h, up, ua, q, r0, r1, d):
    """:func:`bwdesign.sim.kernel.advance` after :func:`_correct`, in its order.

    ``sw`` = (four, phso, delay, compensate, has a disturbance); ``x`` the plant's state,
    ``h`` = (h1, h2, h3, hd, hw) the posterior; ``r0``, ``r1`` this sample's and the next
    one's ``(ff, x_d)``; ``d`` this sample's disturbance. Returns the plant's and the
    observer's next states, the applied input, ``u_a`` and ``q``.
    """
    four, phso, delay, compensate = sw[0], sw[1], sw[2], sw[3]
    h1, h2, h3, hd, hw = h
    u_next = 0.0
    if not delay:
        applied, q = _law(lw, lm, r0[0], r0[1], h1, h2, hw, q)
    else:
        applied = ua
        if not compensate:
            u_next, q = _law(lw, lm, r0[0], r0[1], h1, h2, hw, q)
    ud = applied + d if sw[4] else applied
    x1, x2, x3 = _plant_step(p, x[0], x[1], x[2], up, applied, ud)
    g3 = hysteresis_jump(m[8], m[9], m[10], h3, up, applied) if phso else h3
    gw = g3 + hd if four else g3
    nh1 = m[0] * h1 + m[1] * h2 + m[2] * gw + m[6] * applied
    h2 = m[3] * h1 + m[4] * h2 + m[5] * gw + m[7] * applied
    h1 = nh1
    hw = g3 + hd if four else g3
    if delay:
        if compensate:
            u_next, q = _law(lw, lm, r1[0], r1[1], h1, h2, hw, q)
        ua = u_next
    return (x1, x2, x3), (h1, h2, g3, hd, hw), applied, ua, q


@njit(cache=True, inline="always")
def _within(limit, vlim, x, h, ua):
    """The state inside the divergence limits (:func:`bwdesign.sim.run.diverged`'s test)."""
    return (
        abs(x[0]) <= limit
        and abs(x[2]) <= limit
        and abs(h[0]) <= limit
        and abs(h[4]) <= limit
        and abs(x[1]) <= vlim
        and abs(h[1]) <= vlim
        and abs(ua) < 1e300
    )


@njit(cache=True, inline="always")
def _fresh(start):
    """A scenario's loop state at ``start``: the plant's state, the posterior (xhat1,
    xhat2, xhat3, dhat, lumped), ``(u_prev, u_a, q, the input's last step)`` and the
    twelve sums of ``out``'s columns 0-9, 19 and 20 (:func:`_sums`)."""
    x = (start[0], start[1], start[2])
    h = (start[3], start[4], start[5], 0.0, start[5])
    u = (start[6], start[6], 0.0, 0.0)
    acc = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    return x, h, u, acc


@njit(cache=True, inline="always")
def _sample(p, sw, K, m, lw, lm, x, h, u, acc, z, inw, track, xdk, r0, r1, d):
    """One sample of one scenario (state as :func:`_fresh`): the correction by ``z``, the
    sums inside the window and :func:`_advance`, the scalar loop's operations in its
    order. Returns the next ``(x, h, u, acc)``."""
    up, ua, q, last_du = u
    sa, sq, mx, s1, s2, s3, m1, m2, m3, dum, sat, d2m = acc
    h = _correct(K, sw[0], z, h[0], h[1], h[2], h[3])
    if inw:
        e = x[0] - xdk
        sa += abs(e)
        sq += e * e
        mx = max(mx, abs(e))
        d1, d2, d3 = h[0] - x[0], h[1] - x[1], h[4] - x[2]
        s1 += d1 * d1
        s2 += d2 * d2
        s3 += d3 * d3
        m1 = max(m1, abs(d1))
        m2 = max(m2, abs(d2))
        m3 = max(m3, abs(d3))
    x, h, applied, ua, q = _advance(p, m, lw, lm, sw, x, h, up, ua, q, r0, r1, d)
    if applied <= lw[5] or applied >= lw[6]:
        sat += 1.0
    du = applied - up
    if inw:
        dum = max(dum, abs(du))
        d2m = max(d2m, abs(du - last_du))
    if track:  # the input's last step is kept from the sample before the window on only
        last_du = du
    acc = (sa, sq, mx, s1, s2, s3, m1, m2, m3, dum, sat, d2m)
    return x, h, (applied, ua, q, last_du), acc


@njit(cache=True, inline="always")
def _sums(out, i, acc):
    """Scenario ``i``'s sums (:func:`_fresh`) into ``out``."""
    out[i, 0], out[i, 1], out[i, 2] = acc[0], acc[1], acc[2]
    out[i, 3], out[i, 4], out[i, 5] = acc[3], acc[4], acc[5]
    out[i, 6], out[i, 7], out[i, 8] = acc[6], acc[7], acc[8]
    out[i, 9], out[i, 19], out[i, 20] = acc[9], acc[10], acc[11]


@njit(cache=True, inline="always")
def _checked(out, i, k, limit, vlim, x, h, u, acc):
    """Scenario ``i`` still inside the divergence limits after sample ``k``; where it left
    them, its step, state (:func:`_stop`) and sums are written and False returned."""
    if _within(limit, vlim, x, h, u[1]):
        return True
    _stop(out, i, k, x[0], x[1], x[2], h[0], h[1], h[4], u[1])
    _sums(out, i, acc)
    return False


@njit(cache=True)
def _observer_batch(plant, model, gains, law, lim, flags, start, ref, noise, dist, out):
    # two scenarios at a time, each one's state and sums in local scalars the compiler
    # keeps in registers (in small arrays, every store could alias the noise and reference
    # rows, so each was reloaded: 52 ns a scenario-step). A sample's chain (the input, its
    # jump through expm1, the plant, the next measurement) feeds the next sample, so one
    # scenario leaves the processor waiting; two independent chains side by side overlap
    # (47.0 -> 39.8 ns a scenario-step). Both advance every sample, without a branch on
    # their state around either (with one, the pair was slower than one at a time): a
    # scenario that leaves the divergence limits has its sums and state written there and
    # is carried on unread. An odd last scenario runs alone (``two``, fixed over the loop).
    # Each scenario's operations are the scalar loop's, in its order.
    n = ref.shape[1] - 1
    ff, xd, win = ref[0], ref[1], ref[2]
    rows = dist.shape[0]
    sw, K, m, lw, lm = _loop_constants(model, gains, law, lim, flags, rows)
    limit, noisy = flags[4], flags[5] != 0.0
    N = plant.shape[0]
    for i in range(0, N, 2):
        two = i + 1 < N
        j = i + 1 if two else i
        pa, va = _plant_row(plant, i)
        pb, vb = _plant_row(plant, j)
        xa, ha, ua, aa = _fresh(start)
        xb, hb, ub, ab = _fresh(start)
        on_a, on_b = True, two
        out[i, 10], out[i, 11] = 1.0, -1.0  # alive, no divergence step
        out[j, 10], out[j, 11] = 1.0, -1.0
        da, db = (i, j) if rows > 1 else (0, 0)
        for k in range(n):
            inw = win[k] != 0.0
            track = inw or win[k + 1] != 0.0
            r0, r1 = (ff[k], xd[k]), (ff[k + 1], xd[k + 1])
            za = xa[0] + noise[i, k] if noisy else xa[0]
            zb = xb[0] + noise[j, k] if noisy else xb[0]
            dka = dist[da, k] if rows > 0 else 0.0
            dkb = dist[db, k] if rows > 0 else 0.0
            xa, ha, ua, aa = _sample(
                pa, sw, K, m, lw, lm, xa, ha, ua, aa, za, inw, track, xd[k], r0, r1, dka
            )
            if two:
                xb, hb, ub, ab = _sample(
                    pb, sw, K, m, lw, lm, xb, hb, ub, ab, zb, inw, track, xd[k], r0, r1, dkb
                )
            if on_a:
                on_a = _checked(out, i, k, limit, va, xa, ha, ua, aa)
            if on_b:
                on_b = _checked(out, j, k, limit, vb, xb, hb, ub, ab)
            if not (on_a or on_b):
                break
        if on_b:
            _sums(out, j, ab)
        if on_a:
            _sums(out, i, aa)


def observer_trace(plant, consts, ref, noise, dist, trace):
    """One scenario of :func:`observer_batch`, its record kept: the sample loop of
    :func:`bwdesign.sim.simulate` (``fast``), the same floats to the bit.

    ``plant`` (1, 12), ``consts``, ``ref`` and ``dist`` as there; ``noise`` (1, n), read at
    every sample. ``trace`` (n + 1, 9) is written: row ``k < n`` the true state, the
    posterior estimate (x1hat, x2hat, the lumped x3hat), the applied input and the
    measurement at sample ``k``; row ``n`` whether the run stayed within the divergence
    limits (1.0), the sample where it left them (-1: it did not) and the state there
    (x1, x2, x3, xhat1, xhat2, xhat_lumped, u_a). Rows after a divergence are not written.
    """
    _observer_trace(plant, *consts, ref, noise, dist, trace)


@njit(cache=True)
def _observer_trace(plant, model, gains, law, lim, flags, start, ref, noise, dist, trace):
    n = ref.shape[1] - 1
    ff, xd = ref[0], ref[1]
    sw, K, m, lw, lm = _loop_constants(model, gains, law, lim, flags, dist.shape[0])
    limit = flags[4]
    p, vlim = _plant_row(plant, 0)
    x = (start[0], start[1], start[2])
    h = (start[3], start[4], start[5], 0.0, start[5])
    up, ua, q = start[6], start[6], 0.0
    trace[n, 0], trace[n, 1] = 1.0, -1.0
    for k in range(n):
        z = x[0] + noise[0, k]
        h = _correct(K, sw[0], z, h[0], h[1], h[2], h[3])
        trace[k, 0], trace[k, 1], trace[k, 2] = x
        trace[k, 3], trace[k, 4], trace[k, 5] = h[0], h[1], h[4]
        trace[k, 7] = z
        d = dist[0, k] if sw[4] else 0.0
        r0, r1 = (ff[k], xd[k]), (ff[k + 1], xd[k + 1])
        x, h, applied, ua, q = _advance(p, m, lw, lm, sw, x, h, up, ua, q, r0, r1, d)
        trace[k, 6] = applied
        up = applied
        if not _within(limit, vlim, x, h, ua):
            trace[n, 0], trace[n, 1] = 0.0, k
            trace[n, 2], trace[n, 3], trace[n, 4] = x
            trace[n, 5], trace[n, 6], trace[n, 7], trace[n, 8] = h[0], h[1], h[4], ua
            break


@njit(cache=True)
def baseline_batch(plant, law, ref, flags, start, noise, dist, out):
    """Run a baseline loop (:func:`bwdesign.control.baselines.pid_step`) for every scenario.

    ``plant``, ``noise``, ``dist`` and ``out`` as :func:`observer_batch` (the estimation
    columns stay 0); ``law`` = kp, ki, da, db, dt, lo, hi; ``ref`` = ff, x_d, in-window;
    ``flags`` = delay, divergence limit, has noise; ``start`` = x1, x2, x3, u_prev, q0.
    """
    n = ref.shape[1] - 1
    ff, xd, win = ref[0], ref[1], ref[2]
    kp, ki, da, db, cdt, lo, hi = law[0], law[1], law[2], law[3], law[4], law[5], law[6]
    delay, limit, noisy = flags[0] != 0.0, flags[1], flags[2] != 0.0
    rows = dist.shape[0]
    for i in range(plant.shape[0]):
        p, vlim = _plant_row(plant, i)
        x1, x2, x3 = start[0], start[1], start[2]
        up = ua = start[3]
        q = start[4]
        dd = 0.0
        zp = start[0]
        drow = i if rows > 1 else 0
        sa = sq = mx = dum = sat = d2m = dup = 0.0
        out[i, 10] = 1.0
        out[i, 11] = -1.0
        for k in range(n):
            inw = win[k] != 0.0
            if inw:
                e = x1 - xd[k]
                sa += abs(e)
                sq += e * e
                mx = max(mx, abs(e))
            z = x1 + noise[i, k] if noisy else x1
            # pid_step, operation for operation
            e = xd[k] - z
            dd = da * dd - db * (z - zp)
            zp = z
            qn = q + cdt * e
            v = ff[k] + kp * e + ki * qn + dd
            hold = 0.0
            if (v > hi and e > 0) or (v < lo and e < 0):
                hold = 1.0
            q = qn + hold * (q - qn)
            u = _clip(v, lo, hi)
            if delay:
                applied = ua
                ua = u
            else:
                applied = u
            uprev = up
            ud = applied + dist[drow, k] if rows > 0 else applied
            x1, x2, x3 = _plant_step(p, x1, x2, x3, uprev, applied, ud)
            up = applied
            if applied <= lo or applied >= hi:
                sat += 1.0
            du = applied - uprev
            if inw:
                dum = max(dum, abs(du))
                d2m = max(d2m, abs(du - dup))
            dup = du
            if not (abs(x1) <= limit and abs(x3) <= limit and abs(x2) <= vlim and abs(ua) < 1e300):
                _stop(out, i, k, x1, x2, x3, 0.0, 0.0, 0.0, ua)
                break
        out[i, 0], out[i, 1], out[i, 2] = sa, sq, mx
        out[i, 9] = dum
        out[i, 19] = sat
        out[i, 20] = d2m


@njit(cache=True)
def scaled_normals(rng, out, scale):
    """Fill ``out`` with ``scale * rng.standard_normal(out.size)``, number for number.

    numba's ``Generator`` runs numpy's bit generator and ziggurat, so the numbers are
    numpy's (tested); without numpy's per-call machinery it draws them 1.6x faster.
    """
    for i in range(out.shape[0]):
        out[i] = scale * rng.standard_normal()


def noise_rows(seeds, std, bounded, rows):
    """Row ``i`` of ``rows``: ``std[i] * default_rng(seeds[i]).standard_normal(n)``
    (:func:`bwdesign.sim.run.sensor_noise`), or ``std[i]`` times its sign (``bounded``);
    zeros where ``std[i] <= 0``."""
    # one Generator for every row, its bit generator set to the row's seed's state: numba
    # takes a Generator it has seen again at no cost, while a new one costs about 50 us
    # per call to type and unbox (a third of the noise of a 5000-sample row)
    rng = np.random.Generator(np.random.PCG64(0))
    for i in range(rows.shape[0]):
        row = rows[i]
        s = float(std[i])
        if s <= 0:
            row[:] = 0.0
            continue
        # default_rng(seed) is Generator(PCG64(seed)): the same state, the same numbers;
        # numba's Generator draws numpy's numbers (the same PCG64 and ziggurat), 1.6x
        # faster, straight into the row
        rng.bit_generator.state = np.random.PCG64(int(seeds[i])).state
        if not bounded:
            scaled_normals(rng, row, s)
        else:  # std * sign(standard_normal(n))
            scaled_normals(rng, row, 1.0)
            np.sign(row, out=row)
            row *= s


def _drawn_noise(drawn, n):
    """The ``(N, n)`` noise ``(seeds, std, bounded)`` describes (:func:`noise_rows`), the
    noise itself when given as an array, or the ``(1, 1)`` placeholder of a run without
    noise (``None``)."""
    if drawn is None:
        return np.zeros((1, 1))
    if isinstance(drawn, np.ndarray):
        return drawn
    seeds, std, bounded = drawn
    rows = np.empty((len(seeds), n))
    noise_rows(seeds, std, bounded, rows)
    return rows


def observer_drawn(plant, consts, ref, drawn, dist, out):
    """:func:`observer_batch` with the noise drawn here from ``drawn`` (:func:`_drawn_noise`)."""
    observer_batch(plant, consts, ref, _drawn_noise(drawn, ref.shape[1] - 1), dist, out)


def baseline_drawn(plant, law, ref, flags, start, drawn, dist, out):
    """:func:`baseline_batch` with the noise drawn here from ``drawn`` (:func:`_drawn_noise`)."""
    baseline_batch(plant, law, ref, flags, start, _drawn_noise(drawn, ref.shape[1] - 1), dist, out)
