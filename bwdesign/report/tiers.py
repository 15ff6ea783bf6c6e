"""The certified-gains report's synthesis per tier (rendered from :attr:`Study.tier_synthesis`).

How the rows are computed: :mod:`bwdesign.study.tiers`.
"""

from __future__ import annotations

from ..study import Study
from ..study.tiers import SEARCH_RTOL
from .document import Document, fmt

__all__ = ["tier_synthesis_section"]


def tier_synthesis_section(doc: Document, study: Study) -> None:
    """Add the per-tier synthesis section (:attr:`Study.tier_synthesis`) to ``doc``."""
    part = study.tier_synthesis
    iu, udot_max, decay = study.config.plant.input_unit, part.udot_max, part.decay
    doc.heading("Synthesis per tier: the largest envelope synthesised gains reach")
    doc.para(
        "For each tier, gains synthesised for that tier (bwdesign.synthesize(..., tier=...)) at "
        f"the stage's synthesis decay {decay:g} 1/s, and the largest |u'| ({iu}/s) the tier "
        "certifies for them with that decay (the re-certification's number, checked outside "
        "the solver): what each tier, the paper's Theorem 1 included, can certify if the gains "
        f"are chosen for it. Feasible = synthesis succeeds at the stage's |u'| <= "
        f"{udot_max:.6g} {iu}/s. theorem1 and lipschitz synthesis maximise the envelope "
        "themselves; sector and sampled synthesise for a requested |u'|, which is searched "
        "(first to the envelope the gains synthesised at the stage's |u'| reach, then x4 "
        f"steps, then bisection to {100 * SEARCH_RTOL:g} %) unless the first answer is "
        "already every rate; the row keeps the best gains found, a lower bound on the tier's "
        "reach. 'unbounded' = certified for every rate."
    )
    body = []
    for r in part.rows:
        body.append(
            [
                r.tier,
                "**yes**" if r.feasible else "no",
                "-" if r.gains is None else "(" + ", ".join(f"{g:.6g}" for g in r.gains) + ")",
                fmt(r.envelope),
                f"{r.decay:g}",
                fmt(r.requested),
                str(r.syntheses),
            ]
        )
    doc.table(
        [
            "tier",
            f"feasible at {udot_max:.4g} {iu}/s",
            "synthesised gains l (1/s, 1/s^2, 1/s)",
            f"envelope ({iu}/s)",
            "decay (1/s)",
            f"synthesised for |u'| ({iu}/s)",
            "syntheses",
        ],
        body,
        id="tier-synthesis",
    )
    t1 = part.row("theorem1")
    if t1.gains is not None:
        doc.para(
            f"theorem1: the envelope {fmt(t1.envelope)} {iu}/s is the corrected Theorem 1 "
            "(2 L ||X|| < 1) in the scaled norm ||S eps||, S = diag(1, 1/sqrt(a1), 1), the state "
            "scaling the synthesis chooses; in the paper's unscaled norm (the certificate "
            f"table's theorem1 tier) the same gains certify {fmt(t1.theorem1_unscaled)} {iu}/s "
            f"with decay >= {t1.decay:g} 1/s."
        )
    else:
        doc.para(f"theorem1: no gains; {t1.reason}.")
