"""The input channels of the robust loop certificate (:mod:`.robust`): two covers.

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
from .response import response_sups

__all__ = ["cover_inputs", "deterministic"]


def cover_inputs(
    st: Any, reference: Reference, data: list[dict[str, Any]], noise_max: float, exact: bool
) -> tuple[np.ndarray, np.ndarray, dict[str, Any]] | None:
    """The reference's terms at every time, per plant; the bound of every input channel.

    Sets ``chan``, ``static`` and ``step_ref`` in each plant's ``data``; returns the
    worst hysteresis bounds ``(x3, j, dh)``, the channel bounds ``W`` and their report.
    ``exact``: the reference's own response (:func:`.response.response_sups`; None when
    it does not cover this reference), else its worst case at every sample.
    """
    n, rhos = st.n, st.rhos
    dmax, dstep = st.dist[0], st.dist[1] * st.lp.dt  # |d|, |d_{k+1} - d_k|
    det = deterministic(st, reference, data) if exact else None
    if exact and det is None:
        return None
    if det is None:
        # sup over every t >= 0 of every reference row, all plants at once (refuses a
        # reference it cannot cover: neither periodic nor settling, or no stated structure)
        sups = sup_abs(reference, st.lp.dt, np.vstack([d["rows"] for d in data]))
        sups = np.split(sups, np.cumsum([len(d["rows"]) for d in data])[:-1])
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
        d["chan"] = chan
        d["static"] += np.array([abs(c @ d["Gib"]) * hv for c in st.statics])
        if dmax > 0:
            d["static"] = d["static"] + np.array([abs(c @ d["Gid"]) * dmax for c in st.statics])
    chan = np.max([d["chan"] for d in data], axis=0)
    hb = np.max([d["hyst"] for d in data], axis=0)
    rem = disturbance_remainder(max(d["a3"] for d in data), st.dist[1], st.lp.dt)
    W = np.concatenate([chan, [hb[1], hb[2], noise_max, dstep], rem])
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
