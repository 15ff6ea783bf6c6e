"""The stage TOML an identification writes: plant, sampling, reference, envelope, uncertainty."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .._version import __version__
from .data import IdentificationData
from .result import IdentificationResult

__all__ = ["stage_toml"]


def _comment(text: str, width: int = 96) -> list[str]:
    words, lines, cur = text.split(), [], "#"
    for w in words:
        if len(cur) + 1 + len(w) > width:
            lines.append(cur)
            cur = "#  "
        cur += " " + w
    lines.append(cur)
    return lines


def _records_head(result: IdentificationResult, records: list[IdentificationData]) -> list[str]:
    """The header lines naming the record(s) fitted."""
    if len(records) == 1:
        data = records[0]
        return [
            f"# Identified by bwdesign {__version__} from {data.source or 'a record'}:",
            f"# {data.n} samples at dt = {data.dt:.9g} s. ",
        ]
    head = [
        f"# Identified by bwdesign {__version__} from {len(records)} records fitted together "
        "(one parameter set, a sensor offset and initial state each):"
    ]
    for k, (data, rec) in enumerate(zip(records, result.records, strict=True)):
        head.append(
            f"#   {k + 1}. {data.source or 'a record'}: {data.n} samples at dt = {data.dt:.9g} s, "
            f"fit {rec['fit_percent']:.3f} %, sensor offset {rec['offset']:.6g} um"
        )
    return head + ["# [sampling] and [reference] come from record 1. "]


def _extensions_head(result: IdentificationResult) -> list[str]:
    """The ``[identification]`` comment block: which model extensions were chosen and why."""
    ext = result.extensions
    if not ext:
        return []
    chosen = ", ".join(ext["chosen"]) or "none"
    lines = _comment(
        f"[identification] model extensions chosen: {chosen}. [plant] is the Bouc-Wen part "
        f"of that fit. Rule: {ext['criterion']}."
    )
    for name, row in ext["candidates"].items():
        value = ""
        if row.get("chosen") and "tau_s" in row:
            value = f" (tau {1e3 * row['tau_s']:.4g} ms, input delay {row['delay_samples']})"
        elif row.get("chosen") and "weights" in row:
            pairs = zip(row["taus_s"], row["weights"], strict=True)
            value = " (weights " + ", ".join(f"{w:.4g} um/V at {t:g} s" for t, w in pairs) + ")"
        elif row.get("chosen") and "slopes_per_s" in row:
            value = " (um/s: " + ", ".join(f"{v:.4g}" for v in row["slopes_per_s"]) + ")"
        lines += _comment(f"  {name}: {row['reason']}{value}")
    return lines


def _disturbance_body(result: IdentificationResult) -> list[str]:
    """The ``[uncertainty.disturbance]`` table and how it was computed."""
    if result.disturbance is None:
        return []
    how = result.unexplained
    cov = "not measured" if result.coverage is None else f"{100 * result.coverage:.2f} %"
    return [
        "",
        *_comment(
            f"What the Bouc-Wen model does not explain, as a slowly varying input-equivalent "
            f"disturbance: {how['rule']} (window {1e3 * how['window_s']:g} ms, at least "
            f"{how['min_window_samples']} samples). Coverage of the held-out output by the "
            f"band over the box's corners plus this bound: {cov}."
        ),
        result.disturbance.to_toml().rstrip("\n"),
    ]


def stage_toml(
    result: IdentificationResult, data: IdentificationData | Sequence[IdentificationData]
) -> str:
    """A stage file every bwdesign command accepts, with the intervals in [uncertainty].

    ``data``: the training record, or the records fitted together (the header
    lists each one's fit and offset; ``[sampling]`` and ``[reference]`` come from
    the first). ``[reference]`` is a sine over the displacement range of the
    record at its dominant input frequency and ``[envelope]`` is derived from it
    (10 % margin): placeholders for the operating trajectory, which the user
    should replace with their own before certifying.
    """
    records = [data] if isinstance(data, IdentificationData) else list(data)
    data = records[0]
    fp = result.fit_percent
    val = f"{fp['validation']:.3f} %" if fp["validation"] is not None else "no validation record"
    first = _records_head(result, records)
    head = [
        *first[:-1],
        f"{first[-1]}Fit: train {fp['train']:.3f} %, validation {val};",
        f"# residual RMS {result.residual_rms:.4g} um; sensor offset {result.offset:.6g} um; "
        f"input delay {result.delay_samples} sample(s).",
        f"# converged: {result.converged} ({result.reason})",
        "# Not determined by the record: "
        + (", ".join(n for n, ok in result.determined.items() if not ok) or "none"),
    ]
    for note in result.diagnostics:
        head += _comment("- " + note)
    head += _extensions_head(result)
    y = data.y - result.offset
    amp = 0.5 * float(np.ptp(y))
    centre = float(np.min(y)) + amp
    u = data.u - np.mean(data.u)
    spec = np.abs(np.fft.rfft(u * np.hanning(u.size)))
    freqs = np.fft.rfftfreq(u.size, data.dt)
    f_dom = float(freqs[1 + int(np.argmax(spec[1:]))])
    body = [
        "",
        result.params.to_toml().rstrip("\n"),
        "",
        "[sampling]",
        f"dt = {data.dt!r}",
        "",
        "# Placeholder operating trajectory (the record's range at its dominant input",
        "# frequency): replace it with the trajectory the stage will track.",
        "[reference]",
        'kind = "sine"',
        f"amplitude = {amp!r}",
        f"offset = {centre!r}",
        f"frequency = {f_dom!r}",
        "",
        "[envelope]",
        "from_reference = true",
        "margin = 1.1",
        "",
        "# Placeholder eq. (12) constants (the paper's Section 5 values): tune them.",
        "[controller]",
        "lambda1 = 1.0",
        "lambda2 = 2.0",
        "",
        "# 95 % intervals of the fit as absolute half-widths; inf = not determined.",
        result.to_uncertainty().to_toml().rstrip("\n"),
        *_disturbance_body(result),
    ]
    return "\n".join(head + body) + "\n"
