"""Export a baseline controller (PI, PID, PI + Prandtl–Ishlinskii) as dependency-free C99.

:func:`export_baseline_c` writes ``PREFIX.h``, ``PREFIX.c`` (the law of
:func:`bwdesign.control.baselines.pid_step` and, for ``pi-piff``, the inverse
Prandtl–Ishlinskii operator of :class:`~bwdesign.control.baselines.PrandtlFeedforward`,
each with the Python operations in their order), ``harness.c`` (reads the measurement
and the reference per sample, prints ``u_k`` with ``%.17g``) and ``export.json``. Every
constant is a hexadecimal literal, exact in the chosen precision
(:mod:`bwdesign.codegen.literals`). float64 reproduces the Python loop's inputs bit for
bit; float32 within a stated fraction of the input range (``tests/test_baselines.py``).

The ``pi-bwff`` baseline is not exported: its feedforward solves the exact inverse
Bouc–Wen relation per sample with :func:`scipy.optimize.brentq`
(:func:`bwdesign.model.envelope.feedforward_input`), whose iterates C would not
reproduce bit for bit; export ``pi`` and feed it that feedforward.
"""

from __future__ import annotations

import math
from typing import Any

from .._version import __version__
from ..control.baseline_tuning import analyze_baseline
from ..control.baselines import BaselineController
from ..control.loop import ClosedLoop
from ..errors import ConfigError, InputError
from ..model.config import StageConfig
from ..output.files import prepare_directory
from ..output.jsonenc import dump_json
from .export import CExport, check_prefix, fill
from .literals import CTypes

__all__ = ["EXPORTED_BASELINES", "baseline_c_sources", "export_baseline_c"]

#: The baselines ``export-c --controller`` writes.
EXPORTED_BASELINES = ("pi", "pid", "pi-piff")
_TITLES = {
    "pi": "PI on the measured output",
    "pid": "PID on the measured output (filtered derivative on the measurement)",
    "pi-piff": "PI on the measured output plus the inverse Prandtl-Ishlinskii feedforward",
}


def _ff_code(ct: CTypes, base: dict[str, str], ctrl: BaselineController) -> dict[str, str]:
    """The feedforward's prototypes, implementation and harness lines (empty without one)."""
    p, r, lit = base["prefix"], ct.real, ct.literal
    if ctrl.feedforward is None:
        return {"ff_prototypes": "", "ff_code": "", "ff_state": "", "ff_step": "        ff = 0;"}
    ff = ctrl.feedforward
    inv = ff.inverse
    n = inv.n
    thresholds = ", ".join(lit(v) for v in inv.thresholds)
    weights = ", ".join(lit(v) for v in inv.weights)
    terms = "".join(f"    out = out + f->z[{i}] * W[{i}];\n" for i in range(1, n))
    proto = (
        f"\n/* The inverse Prandtl-Ishlinskii operator: {n} play operators. */\n"
        f"typedef struct {{\n    {r} z[{n}];\n}} {p}_ff;\n\n"
        f"/* The quasi-static target x_d + (a2 x_d' + x_d'')/a1 of the reference triple. */\n"
        f"{r} {p}_ff_target({r} xm, {r} vm, {r} am);\n"
        f"void {p}_ff_init({p}_ff *f, {r} v0);\n"
        f"/* The feedforward input ({base['input_unit']}) for the target v. */\n"
        f"{r} {p}_ff_step({p}_ff *f, {r} v);\n"
    )
    code = (
        f"\nstatic const {r} A1 = {lit(ff.a1)}, A2 = {lit(ff.a2)}, SHIFT = {lit(inv.shift)};\n"
        f"static const {r} R[{n}] = {{{thresholds}}};\n"
        f"static const {r} W[{n}] = {{{weights}}};\n\n"
        f"{r} {p}_ff_target({r} xm, {r} vm, {r} am)\n{{\n"
        f"    return xm + (A2 * vm + am) / A1;\n}}\n\n"
        f"void {p}_ff_init({p}_ff *f, {r} v0)\n{{\n    int i;\n"
        f"    for (i = 0; i < {n}; i++) {{\n        f->z[i] = v0 - SHIFT;\n    }}\n}}\n\n"
        f"{r} {p}_ff_step({p}_ff *f, {r} v)\n{{\n    const {r} x = v - SHIFT;\n"
        f"    {r} out;\n    int i;\n"
        f"    for (i = 0; i < {n}; i++) {{\n"
        f"        const {r} lo = x - R[i], hi = x + R[i];\n"
        f"        const {r} m = f->z[i] < hi ? f->z[i] : hi;\n"
        f"        f->z[i] = lo > m ? lo : m;\n    }}\n"
        f"    out = f->z[0] * W[0];\n{terms}    return out + {lit(inv.offset)};\n}}\n"
    )
    step = (
        f"        {{\n            const {r} v = {p}_ff_target(({r})xm, ({r})vm, ({r})am);\n"
        f"            if (first) {{\n                {p}_ff_init(&f, v);\n            }}\n"
        f"            ff = {p}_ff_step(&f, v);\n        }}"
    )
    return {
        "ff_prototypes": proto,
        "ff_code": code,
        "ff_state": f"    {p}_ff f;",
        "ff_step": step,
    }


def _law(ct: CTypes, ctrl: BaselineController) -> dict[str, str]:
    c, lit = ctrl.constants(), ct.literal
    hold = saturation = ""
    if math.isfinite(c.hi):
        hold += (
            f"    if (v > {lit(c.hi)} && e > {lit(0.0)}) {{\n        hold = {lit(1.0)};\n    }}\n"
        )
        saturation += f"    if (v > {lit(c.hi)}) {{\n        return {lit(c.hi)};\n    }}\n"
    if math.isfinite(c.lo):
        hold += (
            f"    if (v < {lit(c.lo)} && e < {lit(0.0)}) {{\n        hold = {lit(1.0)};\n    }}\n"
        )
        saturation = (
            f"    if (v < {lit(c.lo)}) {{\n        return {lit(c.lo)};\n    }}\n" + saturation
        )
    return {
        "kp": lit(c.kp),
        "ki": lit(c.ki),
        "da": lit(c.da),
        "db": lit(c.db),
        "dt": lit(c.dt),
        "hold": hold,
        "saturation": saturation,
    }


def baseline_c_sources(
    config: StageConfig,
    kind: str,
    *,
    precision: str = "float64",
    prefix: str = "bw",
    gains: Any = None,
    phase_margin: float = 60.0,
    delay: bool = False,
    allow_unbounded: bool = False,
) -> tuple[dict[str, str], dict[str, Any]]:
    """The files of :func:`export_baseline_c` as text, and ``export.json``'s content.

    The controller is the stage's :meth:`ClosedLoop.baseline_from_config` (tuned by the
    rule unless ``gains``; the ``[controller]`` input limits).

    Raises
    ------
    InputError
        ``kind`` not exported (``pi-bwff``: module docstring) or unknown, bad prefix.
    ConfigError
        No ``[sampling]`` dt.
    """
    if kind == "pi-bwff":
        raise InputError(
            "the pi-bwff baseline is not exported: its inverse Bouc-Wen feedforward solves a "
            "scalar equation per sample with scipy's brentq, which C would not reproduce bit "
            "for bit; export --controller pi and feed it that feedforward"
        )
    if kind not in EXPORTED_BASELINES:
        raise InputError(
            f"export-c --controller takes {', '.join(EXPORTED_BASELINES)}, got {kind!r}"
        )
    ct = CTypes(precision)
    prefix = check_prefix(prefix)
    if config.dt is None:
        raise ConfigError(f"{config.source or 'config'}: export-c needs [sampling] dt")
    loop = ClosedLoop.baseline_from_config(
        config, kind, gains=gains, phase_margin=phase_margin, delay=delay,
        allow_unbounded=allow_unbounded,
    )  # fmt: skip
    ctrl = loop.controller
    analysis = analyze_baseline(ctrl, config.plant, delay=delay)
    params = config.plant
    base = {
        "prefix": prefix,
        "PREFIX": prefix.upper(),
        "version": __version__,
        "input_unit": params.input_unit,
        "length_unit": params.length_unit,
        **ct.names(),
    }
    ff = _ff_code(ct, base, ctrl)
    how = ctrl.tuning["rule"] if ctrl.tuning else "explicit gains"
    summary = "\n".join(
        f" * {line}"
        for line in (
            f"kp = {ctrl.kp:.17g}, ki = {ctrl.ki:.17g}, kd = {ctrl.kd:.17g}, tf = {ctrl.tf}",
            f"gains from: {how}",
            f"input limits: {ctrl.u_limits} (anti-windup: conditional integration)",
            f"nominal linear loop: {analysis.describe()}",
        )
    )
    vals = dict(
        base, kind=kind, title=_TITLES[kind], stage=params.name or "(unnamed)",
        sha256=config.sha256 or "-", guard=f"{prefix.upper()}_H", summary=summary,
    )  # fmt: skip
    files = {
        f"{prefix}.h": fill("baseline.h.tmpl", **vals, dt=ct.literal(ctrl.dt), **ff),
        f"{prefix}.c": fill("baseline.c.tmpl", **vals, **_law(ct, ctrl), **ff),
        "harness.c": fill("baseline_harness.c.tmpl", **vals, **ff),
    }
    document = {
        "bwdesign": __version__,
        "precision": precision,
        "prefix": prefix,
        "controller": ctrl.to_dict(),
        "nominal_loop": analysis.to_dict(),
        "delay": bool(delay),
    }
    files["export.json"] = dump_json(document) + "\n"
    return files, document


def export_baseline_c(
    config: StageConfig,
    out_dir: Any,
    kind: str,
    *,
    precision: str = "float64",
    prefix: str = "bw",
    gains: Any = None,
    phase_margin: float = 60.0,
    delay: bool = False,
    allow_unbounded: bool = False,
    force: bool = False,
) -> CExport:
    """Write the C of the baseline ``kind`` into ``out_dir`` (module docstring).

    ``certified`` of the result is whether the nominal linear loop is stable (a baseline
    has no certificate); ``summary`` is that analysis.
    """
    target = prepare_directory(out_dir, command="export-c", force=force, what="--out")
    files, document = baseline_c_sources(
        config, kind, precision=precision, prefix=prefix, gains=gains,
        phase_margin=phase_margin, delay=delay, allow_unbounded=allow_unbounded,
    )  # fmt: skip
    with target.stage() as stage:
        for name, text in files.items():
            stage.write_text(name, text)
    return CExport(
        out_dir=target.path,
        files=tuple(files),
        certified=bool(document["nominal_loop"]["stable"]),
        summary=document["nominal_loop"],
        document=document,
    )
