"""The input channels of the robust loop certificate (:mod:`.robust`) and the bounds
computed from them beside the ellipsoid: its input steps and the per-plant peaks.

The reference enters the error system through its terms ``r_k = M sigma(t_k)``. Two
ways to bound what they do; :func:`bwdesign.certify_robust` certifies with both and
keeps the smaller tracking bound (each is a certificate on its own):

- *per sample* (the quasi-static split of :mod:`.robust`): ``z = z~ + G^-1 w_slow``,
  the increments of the reference terms are inputs of the ellipsoid, each bounded at
  every time by :func:`~bwdesign.model.reference_cover.sup_abs`; they may change sign
  every sample, which no reference does;
- *exact*: ``z = zr + G^-1 b_x3 x3 + z~`` with ``zr`` the loop's own response to the
  reference at the middle ``rho_c`` of the ``rho`` interval, computed at every sample
  in steady state by :func:`.response.response_sups`; what is left for the ellipsoid
  is the coupling ``(rho_k - rho_c) E zr`` (PHSO), bounded by ``(rho_hi - rho_lo) / 2
  sup |E zr|``. The
  tracking bound's reference part is then the exact steady response, not a worst case.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..model.reference_cover import sup_abs
from ..model.references import Reference
from .ellipsoid import disturbance_remainder
from .peak import l1_norms, peak_bounds, peak_parts
from .response import response_sups

__all__ = [
    "cover_inputs",
    "deterministic",
    "input_step_bound",
    "plant_peaks",
    "copy_level",
    "tracking_parts",
    "PARTS",
]


def cover_inputs(
    st: Any,
    reference: Reference,
    data: list[dict[str, Any]],
    noise_max: float,
    exact: bool,
    kept: dict[bool, Any] | None = None,
) -> tuple[np.ndarray, np.ndarray, dict[str, Any]] | None:
    """The reference's terms at every time, per plant; the bound of every input channel.

    Sets ``chan``, ``static`` and ``step_ref`` in each plant's ``data``; returns the
    worst hysteresis bounds ``(x3, j, dh)``, the channel bounds ``W`` and their report.
    ``exact``: the reference's own response (:func:`.response.response_sups`; None when
    it does not cover this reference), else its worst case at every sample. ``kept``:
    the reference's part by ``exact``, computed on the first call that passes it and
    read by the next (the plants' reference rows must be the same).
    """
    n, rhos = st.n, st.rhos
    dmax, dstep = st.dist[0], st.dist[1] * st.lp.dt  # |d|, |d_{k+1} - d_k|
    kept = {} if kept is None else kept
    if exact not in kept:
        if exact:
            kept[exact] = deterministic(st, reference, data)
        else:
            # sup over every t >= 0 of every reference row, all plants at once (refuses a
            # reference it cannot cover: neither periodic nor settling, no stated structure)
            sups = sup_abs(reference, st.lp.dt, np.vstack([d["rows"] for d in data]))
            kept[exact] = np.split(sups, np.cumsum([len(d["rows"]) for d in data])[:-1])
    det = kept[exact] if exact else None
    sups = None if exact else kept[exact]
    if exact and det is None:
        return None
    half = (rhos[-1] - rhos[0]) / 2
    for i, d in enumerate(data):
        hv = d["hyst"][0]
        if det is not None:  # the reference's own response (response_sups)
            s = det[i]
            chan = np.zeros(n)
            if d["E"] is not None:
                chan = half * s[3 : 3 + n] + half * np.abs(d["E"] @ d["Gib"]) * hv
            d["static"] = s[:3].copy()
            d["step_ref"] = np.full(
                len(rhos), s[-1] + (half * s[3 + n] if d["E"] is not None else 0)
            )
        else:
            d["sup"] = sups[i]
            chan = d["sup"][:n].copy()
            if d["E"] is not None:
                chan += half * (d["sup"][n : 2 * n] + np.abs(d["E"] @ d["Gib"]) * hv)
            k = 2 * n if d["E"] is not None else n
            d["static"] = d["sup"][k : k + 3].copy()
            d["step_ref"] = d["sup"][k + 3 :]
        if (
            dmax > 0 and d["E"] is not None
        ):  # the rho coupling of the disturbance's quasi-static part
            chan += half * np.abs(d["E"] @ d["Gid"]) * dmax
        jv = d["hyst"][1]
        if d["E"] is not None:  # the rho coupling of the slow jump's (0 for a fast one)
            chan += half * np.abs(d["E"] @ d["Gie"]) * jv
        d["chan"] = chan
        d["static"] += np.array(
            [abs(c @ d["Gib"]) * hv + abs(c @ d["Gie"]) * jv for c in st.statics]
        )
        if dmax > 0:
            d["static"] = d["static"] + np.array([abs(c @ d["Gid"]) * dmax for c in st.statics])
    chan = np.max([d["chan"] for d in data], axis=0)
    hb = np.max([d["hyst"] for d in data], axis=0)
    rem = disturbance_remainder(max(d["a3"] for d in data), st.dist[1], st.lp.dt)
    jchan = max(d["jchan"] for d in data)  # the jump, or its change where it is slow
    W = np.concatenate([chan, [jchan, hb[2], noise_max, dstep], rem])
    input_bounds = {
        "state_channels": chan.tolist(),
        "x3": float(hb[0]),
        "j": float(hb[1]),
        "dh": float(hb[2]),
        "noise": noise_max,
        "reference_terms": "exact response" if det is not None else "worst case per sample",
    }
    if dmax > 0 or dstep > 0:
        input_bounds["disturbance"] = {
            "input_max": dmax,
            "step": dstep,
            "within_sample": rem.tolist(),
        }
    return np.concatenate([hb, rem]), W, input_bounds


def deterministic(st: Any, reference: Reference, data: list[dict]) -> np.ndarray | None:
    """Per plant: sup of the reference's own response (:mod:`.response`) on the rows
    ``statics (3), E (n) and cu' E (PHSO), the input's increment``; None: not covered."""
    Lz, Lr = [], []
    for d in data:
        rows = list(st.statics)
        if d["E"] is not None:
            rows += list(d["E"]) + [st.cu @ d["E"]]
        Lz.append(np.array(rows + [st.cu]))
    R = len(Lz[0])
    Lr = np.zeros((R, 5))
    Lr[-1] = st.su[:5]
    incr = np.zeros(R, bool)
    incr[-1] = True
    A = np.array([d["Ac"] for d in data])
    B = np.array([d["Bref"] for d in data])
    out = response_sups(A, B, st.M, reference, st.lp.dt, (np.array(Lz), Lr, incr))
    return None if out is None or not np.all(np.isfinite(out)) else out


def input_step_bound(st: Any, data: list[dict], dyn, hb: np.ndarray, noise_max: float) -> float:
    """Bound on ``|u_{k+1} - u_k|`` in steady state, over every plant and rho end.

    ``u_{k+1} - u_k = v' z_k + cu' B s_k + su' (s_{k+1} - s_k)`` with
    ``v = (A - I)' cu``, ``z = z~ + G^-1 w_slow`` and ``x3_{k+1} - x3_k = j_k``;
    the disturbance acts on the plant only (``su`` has no entry for it).
    """
    cu, su, n = st.cu, st.su, st.n
    worst = 0.0
    j_, dh_ = float(hb[1]), float(hb[2])
    dmax, (r1, r2) = st.dist[0], (float(hb[3]), float(hb[4]))
    for i, d in enumerate(data):
        Gib, hv = d["Gib"], d["hyst"][0]
        for (A, B), ref in zip(d["mats"], d["step_ref"], strict=True):
            v = (A - np.eye(n)).T @ cu
            total = (
                dyn(v, i)
                + float(ref)
                + abs(v @ Gib + cu @ B[:, 5]) * hv
                + abs(su[5]) * j_
                + (abs(v @ d["Gie"] + cu @ B[:, 6]) + 2 * abs(su[6])) * j_
                + (abs(cu @ B[:, 7]) + 2 * abs(su[7])) * dh_
                + (abs(cu @ B[:, 8]) + 2 * abs(su[8])) * noise_max
            )
            if dmax > 0 or r1 > 0:
                total += (
                    abs(v @ d["Gid"] + cu @ B[:, 9]) * dmax
                    + abs(cu @ B[:, 10]) * r1
                    + abs(cu @ B[:, 11]) * r2
                )
            worst = max(worst, total)
    return worst


def plant_peaks(st: Any, data: list[dict], W: np.ndarray) -> list[np.ndarray] | None:
    """Per plant, :func:`.peak.peak_bounds` of ``|c'z~|`` for the three outputs, of
    ``(A_c - I)'cu . z~`` and (PHSO) of ``cu'E z~``: the input step's ``z~`` part at
    either end of ``rho``. None if any plant has none (then the ellipsoid's stand)."""
    n, out = st.n, []
    for d in data:
        rows, Wp, change = _plant_rows(st, d, W)
        pb = peak_bounds(d["blocks"], st.rhos, Wp, rows, change)
        if pb is None:
            return None
        if d["E"] is None and Wp[n + 1] > 0:  # PHDO: dh also as the copy error's increment
            step, smaller = copy_level(d, Wp[n + 1], rows[:3])
            pb[:3] += smaller - step
        out.append(pb)
    return out


#: The names of the tracking bound's parts (:func:`tracking_parts`), by input channel.
PARTS = (
    "reference and rho coupling",
    "hysteresis jump",
    "jump model error",
    "sensor noise",
    "disturbance step",
    "disturbance within sample",
)


def tracking_parts(st: Any, d: dict, W: np.ndarray) -> dict[str, float] | None:
    """What each input adds to one plant's peak-to-peak tracking bound (:func:`plant_peaks`
    of ``d``, plus its quasi-static part): a dict of :data:`PARTS` (length unit) and
    ``"quasi-static"``. The first is the state channels (the reference terms' increments
    or, with the exact cover, none of them, and every ``rho`` coupling); the jump's is its
    change where it is a slow input. The parts sum to the bound (to rounding: it is
    linear in the channels' bounds)."""
    n = st.n
    rows, Wp, change = _plant_rows(st, d, W)
    # all of plant_peaks' rows: the sums stop where every row's rest is small (.peak)
    parts = peak_parts(d["blocks"], st.rhos, Wp, rows, change)
    if parts is None:
        return None
    p = parts[0]
    if d["E"] is None and Wp[n + 1] > 0:  # PHDO: dh's smaller treatment, as plant_peaks
        step, smaller = copy_level(d, Wp[n + 1], rows[:3])
        p[n + 1] += smaller[0] - step[0]
    groups = (p[:n].sum(), p[n], p[n + 1], p[n + 2], p[n + 3], p[n + 4 :].sum())
    out = {name: float(v) for name, v in zip(PARTS, groups, strict=True)}
    out["quasi-static"] = float(d["static"][0])
    return out


def _plant_rows(st: Any, d: dict, W: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rows :func:`plant_peaks` bounds for plant ``d``, its own channel bounds and
    their changes' bounds (finite for a fast jump whose change is bounded, else inf)."""
    n = st.n
    A_c = np.mean([A for A, _ in d["blocks"]], axis=0)
    rows = np.array(
        [
            *st.statics,
            (A_c - np.eye(n)).T @ st.cu,
            d["E"].T @ st.cu if d["E"] is not None else np.zeros(n),
        ]
    )
    Wp = W.copy()
    Wp[: n + 2] = np.concatenate([d["chan"], [d["jchan"], d["hyst"][2]]])
    change = np.full(len(Wp), np.inf)
    change[n] = d["jdiff"]
    return rows, Wp, change


def copy_level(d: dict, dh: float, rows: np.ndarray) -> np.ndarray:
    """What the PHDO's ``dh`` channel ``(rho - 1) e3 + dh`` adds to ``|rows z~|``, taken
    as a step (``|.| <= dh``) and, less where smaller, as the increment of the copy
    error ``e3`` (``|e3| <= level``, ``.ellipsoid.copy_error_bound``): ``z~ - b e3`` sees
    ``(A - I) b e3``, a level. Returns ``(step, smaller)``."""
    (A, B), n = d["blocks"][0], len(d["blocks"][0][0])
    b, level = B[:, n + 1], d["copy_error"]
    step = l1_norms(A, b[:, None], rows)[:, 0] * dh
    alt = l1_norms(A, ((A - np.eye(n)) @ b)[:, None], rows)[:, 0] * level
    return step, np.minimum(step, alt + np.abs(rows @ b) * level)
