"""Export a baseline controller (PI, PID, PI + a hysteresis feedforward) as dependency-free C99.

:func:`export_baseline_c` writes ``PREFIX.h``, ``PREFIX.c`` (the law of
:func:`bwdesign.control.baselines.pid_step` and, for ``pi-piff``, the inverse
Prandtl–Ishlinskii operator of :class:`~bwdesign.control.baselines.PrandtlFeedforward`,
for ``pi-bwff`` the exact inverse Bouc–Wen model's safeguarded Newton iteration of
:func:`bwdesign.model.inverse.inverse_step`, each with the Python operations in their
order), ``harness.c`` (reads the measurement and the reference per sample, prints ``u_k``
with ``%.17g``) and ``export.json``. Every constant is a hexadecimal literal, exact in the
chosen precision (:mod:`bwdesign.codegen.literals`). float64 reproduces the Python loop's
inputs bit for bit (the inverse's ``expm1``/``log1p`` are the libm calls Python's
``math`` makes); float32 within a stated fraction of the input range
(``tests/test_baselines.py``). The float32 inverse stops its Newton iteration at
:data:`FLOAT32_TOL` relative instead of 1e-14 (below float32's rounding).
"""

from __future__ import annotations

import math
from typing import Any

from .._version import __version__
from ..control.baseline_tuning import analyze_baseline
from ..control.baselines import BaselineController, InverseBoucWenFeedforward, PrandtlFeedforward
from ..control.loop import ClosedLoop
from ..errors import ConfigError, InputError
from ..model.config import StageConfig
from ..model.inverse import MAX_ITER, inverse_bound
from ..model.inverse import TOL as INVERSE_TOL
from ..output.files import prepare_directory
from ..output.jsonenc import dump_json
from .export import CExport, check_prefix, fill, hysteresis_source
from .literals import CTypes

__all__ = ["EXPORTED_BASELINES", "FLOAT32_TOL", "baseline_c_sources", "export_baseline_c"]

#: The baselines ``export-c --controller`` writes.
EXPORTED_BASELINES = ("pi", "pid", "pi-bwff", "pi-piff")
_TITLES = {
    "pi": "PI on the measured output",
    "pid": "PID on the measured output (filtered derivative on the measurement)",
    "pi-bwff": "PI on the measured output plus the exact inverse Bouc-Wen feedforward",
    "pi-piff": "PI on the measured output plus the inverse Prandtl-Ishlinskii feedforward",
}
#: The float32 inverse Bouc-Wen's relative Newton step tolerance: 4 float32 epsilons, above
#: the rounding of its residual (a3 v - a1 h - r cancels to a few float32 ulps of a3 v); on
#: paper_experiment the iteration then stops after at most 3 evaluations, as in float64.
FLOAT32_TOL = 2.0**-21


_HARNESS_FF = (
    "        {{\n            const {r} v = {p}_ff_target(({r})xm, ({r})vm, ({r})am);\n"
    "            if (first) {{\n                {p}_ff_init(&f, v);\n            }}\n"
    "            ff = {p}_ff_step(&f, v);\n        }}"
)


def _ff_code(ct: CTypes, base: dict[str, str], ctrl: BaselineController) -> dict[str, str]:
    """The feedforward's prototypes, implementation and harness lines (empty without one)."""
    p, r = base["prefix"], ct.real
    if ctrl.feedforward is None:
        return {
            "ff_prototypes": "", "ff_code": "", "ff_state": "", "ff_step": "        ff = 0;",
            "includes": "",
        }  # fmt: skip
    make = _piff_code if ctrl.feedforward.kind == "piff" else _bwff_code
    proto, code = make(ct, base, ctrl.feedforward)
    return {
        "ff_prototypes": proto,
        "ff_code": code,
        "ff_state": f"    {p}_ff f;",
        "ff_step": _HARNESS_FF.format(p=p, r=r),
        "includes": "#include <math.h>\n\n" if ctrl.feedforward.kind == "bwff" else "",
    }


def _bwff_code(ct: CTypes, base: dict[str, str], ff: InverseBoucWenFeedforward) -> tuple[str, str]:
    """The exact inverse Bouc-Wen feedforward (:func:`bwdesign.model.inverse.inverse_step`)."""
    p, r, lit = base["prefix"], ct.real, ct.literal
    params = ff.params
    proto = (
        f"\n/* The exact inverse Bouc-Wen model: the previous input u, its last increment du and\n"
        f" * the hysteresis state h. */\n"
        f"typedef struct {{\n    {r} u;\n    {r} du;\n    {r} h;\n}} {p}_ff;\n\n"
        f"/* The target r = x_d'' + a2 x_d' + a1 x_d of the reference triple. */\n"
        f"{r} {p}_ff_target({r} xm, {r} vm, {r} am);\n"
        f"void {p}_ff_init({p}_ff *f, {r} r);\n"
        f"/* The feedforward input ({base['input_unit']}) for the target r. */\n"
        f"{r} {p}_ff_step({p}_ff *f, {r} r);\n"
    )
    tol = INVERSE_TOL if ct.precision == "float64" else FLOAT32_TOL
    code = fill(
        "baseline_bwff.c.tmpl", **base, max_iter=str(MAX_ITER),
        a1=lit(params.a1), a2=lit(params.a2), a3=lit(params.a3),
        sg=lit(1.0 if params.a3 > 0 else -1.0), alpha=lit(params.alpha), beta=lit(params.beta),
        gamma=lit(params.gamma), h_max=lit(inverse_bound(params)), b_scale=lit(1.0001),
        b_pad=lit(1e-12), tol=lit(tol), hysteresis=hysteresis_source(ct),
    )  # fmt: skip
    return proto, code


def _piff_code(ct: CTypes, base: dict[str, str], ff: PrandtlFeedforward) -> tuple[str, str]:
    """The inverse Prandtl-Ishlinskii operator of :class:`PrandtlFeedforward`."""
    p, r, lit = base["prefix"], ct.real, ct.literal
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
    return proto, code


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
        ``kind`` unknown, bad prefix; ``pi-bwff`` for a plant outside the bounded class
        (the inverse's bracket needs the hysteresis bound).
    ConfigError
        No ``[sampling]`` dt.
    """
    if kind not in EXPORTED_BASELINES:
        raise InputError(
            f"export-c --controller takes {', '.join(EXPORTED_BASELINES)}, got {kind!r}"
        )
    ct = CTypes(precision)
    prefix = check_prefix(prefix)
    if kind == "pi-bwff" and not config.plant.bounded_class().bounded:
        raise InputError(
            "the pi-bwff baseline is exported for plants in the bounded Bouc-Wen class only: "
            "the C inverse's bracket needs the hysteresis bound alpha/(beta + gamma)"
        )
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
    if kind == "pi-bwff":
        document["inverse"] = {
            "method": "safeguarded Newton per sample (bwdesign.model.inverse.inverse_step)",
            "tol": INVERSE_TOL if precision == "float64" else FLOAT32_TOL,
            "max_iter": MAX_ITER,
            "h_max": inverse_bound(params),
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
