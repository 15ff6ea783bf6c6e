"""Export the certified discrete observers and tracking controller as dependency-free C99.

:func:`export_c` turns a stage configuration into a directory holding

- ``PREFIX.h``: the state structs, ``init``/``reset``/``predict``/``update``/``step``
  of every sampled observer the package has (PHSO, ESO, and the disturbance
  observer PHDO with its four states and ``PREFIX_phdo_lumped``, the estimate
  ``(x1, x2, x3 + d)`` the controller is fed) and the controller's ``compute``;
  compile-time constants for ``dt`` and the certified ``|u'|`` bound; a comment
  block with the certificate summary (the PHSO's tier and the PHDO's lumped-error
  certificate);
- ``PREFIX.c``: the implementation: the exact hysteresis jump (``expm1``/``log1p``
  and their float forms, the only ``<math.h>`` use), the exact ZOH step, the
  correction; no dynamic memory, no global mutable state, no I/O;
- ``harness.c``: a ``main`` that reads ``u,z`` lines on stdin, runs one observer
  step per line and prints the posterior with ``%.17g`` (and controller modes, and
  ``phdo-loop``: the loop's sample with the controller fed by the PHDO), so a user
  checks the code on their own toolchain;
- ``export.json``: what was exported (gains, K, constants, certificate summary).

``cc -std=c99 DIR/*.c -lm`` builds the harness. Every constant is written as a
C99 hexadecimal floating literal, exact in the chosen precision
(:mod:`bwdesign.codegen.literals`); float32 code uses ``f``-suffixed constants and
the ``f`` math functions, so nothing is promoted to double.

The C step performs the Python classes' float operations in the same order
(``bwdesign.observers``: :class:`~bwdesign.HysteresisObserver`,
:class:`~bwdesign.ExtendedStateObserver`, :class:`~bwdesign.DisturbanceHysteresisObserver`;
``bwdesign.control``:
:class:`~bwdesign.DiscreteTrackingController`, :class:`~bwdesign.TrackingController`),
so float64 agrees with Python to rounding.

Runtime guard: each ``predict`` compares the input step ``|u_k - u_{k-1}|`` with
``DU_MAX = UDOT_MAX * DT``; beyond it the certificate does not cover the step, and
the state's ``uncovered`` flag is set and ``guard_trips`` counts it.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from importlib.resources import files
from pathlib import Path
from string import Template
from typing import Any

from .._version import __version__
from ..certify.disturbance import LumpedCertificate, certify_disturbance
from ..certify.results import CertificateReport
from ..certify.tiers import certify, certify_discrete
from ..control.controllers import DiscreteTrackingController
from ..control.loop import controller_from_config
from ..design.gains import synthesize as synthesize_gains
from ..design.tuning import digital_tuning
from ..errors import ConfigError, InputError, InternalError, NotCertifiedError
from ..model.config import StageConfig
from ..model.params import require_bounded
from ..model.plant import discretize
from ..observers.base import SampledObserver
from ..observers.gains import gains_for_observer
from ..observers.sampled import (
    DisturbanceHysteresisObserver,
    ExtendedStateObserver,
    HysteresisObserver,
)
from ..output.files import prepare_directory
from ..output.jsonenc import dump_json
from .literals import CTypes

__all__ = ["OBSERVERS", "CExport", "export_c", "c_sources", "fill", "check_prefix"]

#: The sampled observers the C library carries, by the name ``--observer`` takes.
OBSERVERS: dict[str, tuple[type[SampledObserver], str]] = {
    "phso": (HysteresisObserver, "hysteresis observer (PHSO, paper eq. 3)"),
    "eso": (ExtendedStateObserver, "extended state observer (ESO, paper eq. 21)"),
    "phdo": (
        DisturbanceHysteresisObserver,
        "disturbance hysteresis observer (PHDO: the PHSO with an integrating disturbance d)",
    ),
}
#: The observers with three states (``PREFIX_observer``); the PHDO has its own struct.
_THREE_STATE = ("phso", "eso")
GAIN_SOURCES = ("config", "synthesize", "digital")
_PREFIX = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,30}")


@dataclass(frozen=True)
class CExport:
    """What :func:`export_c` wrote, and why it may be trusted.

    Attributes
    ----------
    out_dir : Path
    files : tuple of str
        File names written, relative to ``out_dir``.
    certified : bool
        Whether a certificate tier holds for the exported gains at the envelope.
    summary : dict
        The certificate summary written into the header (tier, envelope, decay, dt, hash).
    document : dict
        The content of ``export.json``.
    """

    out_dir: Path
    files: tuple[str, ...]
    certified: bool
    summary: dict[str, Any]
    document: dict[str, Any] = field(repr=False)


def _template(name: str) -> Template:
    return Template(files("bwdesign.codegen").joinpath("templates", name).read_text())


def fill(name: str, **values: Any) -> str:
    try:
        return _template(name).substitute(values)
    except KeyError as err:  # a template asks for a value the exporter does not give
        raise InternalError(f"template {name}: no value for ${err.args[0]}") from None


def hysteresis_source(ct: CTypes) -> str:
    """The exact hysteresis jump in C (``branch``, ``inside_first_branch`` and
    ``hysteresis``, static) for a file that defines ``ALPHA``, ``BETA`` and ``GAMMA``
    before it: the observers' source and the inverse feedforward of the baselines."""
    return fill("hysteresis.c.tmpl", **ct.names())


def check_prefix(prefix: str) -> str:
    if not isinstance(prefix, str) or not _PREFIX.fullmatch(prefix):
        raise InputError(f"prefix must be a C identifier of at most 31 characters, got {prefix!r}")
    return prefix


def _requirements(config: StageConfig, source: str) -> tuple[float, float]:
    missing = []
    if config.dt is None:
        missing.append("[sampling] dt")
    if config.envelope_spec is None:
        missing.append("[envelope] (the |u'| bound the gains are certified for)")
    if config.controller is None and source != "digital":
        missing.append("[controller] (lambda1, lambda2)")
    if config.gains is None and source == "config":
        missing.append("[observer] gains (or --synthesize / --tuning digital)")
    if missing:
        raise ConfigError(f"{config.source or 'config'}: export-c needs {', '.join(missing)}")
    return float(config.dt), config.envelope().udot_max


@dataclass(frozen=True)
class _PhdoGains:
    """The PHDO's gains (continuous ``gains`` or discrete ``K``), its certificate, their origin."""

    gains: tuple[float, ...] | None
    K: tuple[float, ...] | None
    certificate: LumpedCertificate
    origin: str


def _phdo_certified(params, gains, K, udot_max, dt, origin) -> _PhdoGains:
    cert = (
        certify_disturbance(params, gains, udot_max=udot_max, dt=dt)
        if K is None
        else certify_disturbance(params, udot_max=udot_max, dt=dt, discrete=K)
    )
    return _PhdoGains(gains, K, cert, origin)


def _phdo_gains(params, source, dt, udot_max, gains, K, tune) -> _PhdoGains:
    """The PHDO's gains for a gain source, certified by :func:`certify_disturbance`.

    Every source gives the PHDO the lumped form of the 3-state gains it exports, so the
    PHDO's observable part ``(x1, x2, x3 + d)`` has the exported PHSO's poles and the
    whole lumped correction goes to ``d`` (``l3 = 0``):

    - ``config``: the config's ``[observer]`` gains as ``(l1, l2, 0, l3)``
      (:func:`bwdesign.observers.gains.gains_for_observer`, as ``bwdesign sweep`` runs
      the PHDO from a stage file);
    - ``digital``: ``DigitalTuning.observer_gains_for("phdo")`` (the same form of the
      tuning's gains, as ``simulate --observer phdo --tuning digital``);
    - ``synthesize``: the synthesised PHSO gains in the same form (discrete
      ``(k1, k2, 0, k3)`` when the synthesis returns discrete ``K``). The PHDO's own LMI
      synthesis (:func:`bwdesign.certify.disturbance.synthesize_disturbance`) is not
      used: it bounds the decay only, and on ``paper_experiment`` places a pole at
      ``|z| = 1.8e-4`` (``k1 = 0.9998``: the measurement noise passes into the estimate
      nearly unfiltered), and on ``stack_actuator_800hz`` its re-certification ends in
      solver trouble (``optimal_inaccurate``).
    """
    if source == "digital":
        return _phdo_certified(
            params,
            tune.observer_gains_for("phdo"),
            None,
            udot_max,
            dt,
            "the digital tuning's observer_gains_for('phdo') = (l1, l2, 0, l3)",
        )
    what = "the config's [observer] gains" if source == "config" else "the synthesised gains"
    if gains is not None:
        return _phdo_certified(
            params,
            gains_for_observer("phdo", gains),
            None,
            udot_max,
            dt,
            f"{what} in the lumped form (l1, l2, 0, l3)",
        )
    return _phdo_certified(
        params,
        None,
        gains_for_observer("phdo", K),
        udot_max,
        dt,
        f"{what} K in the lumped form (k1, k2, 0, k3)",
    )


def _gains(config, source, dt, udot_max):
    """(continuous gains or None, discrete K or None, certificate report, controller, PHDO).

    The PHDO entry is None when there are no gains to export (synthesis infeasible).
    """
    params = config.plant
    if source == "digital":
        tune = digital_tuning(params, dt)
        gains = tuple(float(g) for g in tune.gains)
        controller = controller_from_config(config, law=tune)
        phdo = _phdo_gains(params, source, dt, udot_max, gains, None, tune)
        return gains, None, certify(params, gains, udot_max=udot_max, dt=dt), controller, phdo
    controller = controller_from_config(config, form="discrete")
    if source == "synthesize":
        decay = (config.synthesis or {}).get("decay", 100.0)
        syn = synthesize_gains(
            params,
            udot_max=udot_max,
            decay=decay,
            pole_radius=(config.synthesis or {}).get("pole_radius"),
            dt=dt,
        )
        if not syn.feasible:
            return None, None, syn.report, controller, None
        if syn.gains is not None:
            gains = tuple(syn.gains)
            phdo = _phdo_gains(params, source, dt, udot_max, gains, None, None)
            return gains, None, syn.report, controller, phdo
        K = tuple(syn.discrete_gains)
        phdo = _phdo_gains(params, source, dt, udot_max, None, K, None)
        rep = certify_discrete(params, K, udot_max=udot_max, dt=dt)
        return None, K, rep, controller, phdo
    gains = tuple(config.gains)
    phdo = _phdo_gains(params, source, dt, udot_max, gains, None, None)
    return gains, None, certify(params, gains, udot_max=udot_max, dt=dt), controller, phdo


def _summary(
    config, rep: CertificateReport | None, udot_max, dt, source, phdo: _PhdoGains | None
) -> dict[str, Any]:
    """The certificate summary: ``certified`` when every exported observer's gains are.

    ``tier`` .. ``decay_rate`` are the certificate of the 3-state gains (the PHSO's
    error, :func:`bwdesign.certify`; the ESO runs the same gains); ``phdo`` is the
    PHDO's lumped-error certificate (:func:`bwdesign.certify_disturbance`).
    """
    best = None if rep is None else rep.best
    tier = None if best is None else rep.tier(best)
    cert = None if phdo is None else phdo.certificate
    return {
        "certified": best is not None and cert is not None and cert.holds,
        "tier": best,
        "udot_max": udot_max,
        "max_udot": None if tier is None else tier.max_udot,
        "decay_rate": None if tier is None else tier.decay_rate,
        "dt": dt,
        "gains_from": source,
        "config": Path(config.source).name if config.source else "",
        "config_sha256": config.sha256,
        "phdo": None
        if phdo is None
        else {
            "certified": cert.holds,
            "tier": cert.tier,
            "udot_max": cert.udot_max,
            "dt": dt,
            "claim": cert.claim,
            "status": cert.status,
            "split": cert.split,
            "gains_from": phdo.origin,
        },
    }


def _comment(
    summary: dict[str, Any], gains, K: dict[str, list[float]], params, phdo: _PhdoGains
) -> str:
    def num(v):
        return "-" if v is None else f"{v:.10g}"

    top = summary["max_udot"]
    reach = (
        "the tier holds for every rate up to its search limit"
        if top is not None and not math.isfinite(top)
        else f"the tier holds up to {num(top)} V/s"
    )
    lines = [
        f"stage {params.name or '(unnamed)'}: config {summary['config'] or '-'}, "
        f"sha256 {summary['config_sha256'] or '-'}",
        f"observer gains from {summary['gains_from']}: continuous l = "
        + ("-" if gains is None else "(" + ", ".join(f"{g:.17g}" for g in gains) + ")"),
    ]
    lines += [
        f"  {name}: K = (" + ", ".join(f"{k:.17g}" for k in ks) + ")" for name, ks in K.items()
    ]
    if summary["tier"] is not None:
        lines += [
            f"PHSO/ESO gains CERTIFIED by the {summary['tier']} tier for |u'| <= "
            f"{num(summary['udot_max'])} V/s at dt = {num(summary['dt'])} s ({reach}), "
            f"certified decay {num(summary['decay_rate'])} 1/s.",
        ]
    else:
        lines += [
            f"PHSO/ESO gains NOT CERTIFIED: no tier holds for |u'| <= "
            f"{num(summary['udot_max'])} V/s at dt = {num(summary['dt'])} s "
            "(exported with --allow-uncertified).",
        ]
    cert = phdo.certificate
    lines += [
        f"PHDO gains from {phdo.origin}: "
        + (
            "continuous l = (" + ", ".join(f"{g:.17g}" for g in phdo.gains) + ")"
            if phdo.gains is not None
            else "discrete K (below)"
        ),
        (
            f"PHDO lumped error CERTIFIED by the {cert.tier} tier of certify_disturbance"
            if cert.holds
            else f"PHDO lumped error NOT CERTIFIED ({cert.status}; exported with "
            "--allow-uncertified)"
        )
        + f" for |u'| <= {num(cert.udot_max)} V/s at dt = {num(summary['dt'])} s: the claim is",
        "  that (x1, x2, x3 + d) converges to 0 and x3, d stay bounded; x3 and d converge",
        "  separately only while the input moves. The controller is fed (x1, x2, x3 + d).",
    ]
    return "\n".join(" * " + line for line in lines)


def _udot_max_comment(summary: dict[str, Any]) -> str:
    """The header's line on UDOT_MAX: "certified" only when the export is."""
    if summary["certified"]:
        return "The input-rate bound |u'| (V/s) the observer gains are certified for."
    return (
        "The input-rate bound |u'| (V/s) asked for (the stage's envelope); the exported gains "
        "are NOT certified for it (exported with --allow-uncertified)."
    )


def c_sources(
    config: StageConfig,
    *,
    precision: str = "float64",
    observer: str = "phso",
    prefix: str = "bw",
    gains_from: str = "config",
    allow_uncertified: bool = False,
    allow_unbounded: bool = False,
) -> tuple[dict[str, str], bool, dict[str, Any], dict[str, Any]]:
    """The generated files as text, without writing them (see :func:`export_c`).

    Returns
    -------
    files : dict of str to str
        File name to content.
    certified : bool
    summary : dict
    document : dict
        The content of ``export.json``.
    """
    ct = CTypes(precision)
    prefix = check_prefix(prefix)
    if observer not in OBSERVERS:
        raise InputError(f"unknown observer {observer!r}; choose one of {', '.join(OBSERVERS)}")
    if gains_from not in GAIN_SOURCES:
        raise InputError(f"gains_from must be one of {', '.join(GAIN_SOURCES)}, got {gains_from!r}")
    params = config.plant
    require_bounded(params, allow_unbounded)
    dt, udot_max = _requirements(config, gains_from)
    gains, K, rep, controller, phdo = _gains(config, gains_from, dt, udot_max)
    summary = _summary(config, rep, udot_max, dt, gains_from, phdo)
    if not summary["certified"] and not allow_uncertified:
        why = _uncertified_reason(summary, gains, K, phdo, udot_max, dt)
        raise NotCertifiedError(f"{why}; nothing exported (--allow-uncertified exports anyway)")
    if gains is None and K is None:
        raise NotCertifiedError("synthesis found no gains to export")

    lit = ct.literal
    names = ct.names()
    base = {
        "prefix": prefix,
        "PREFIX": prefix.upper(),
        "version": __version__,
        **names,
    }
    Ks = _observer_gains(params, gains, K, phdo, dt, allow_unbounded)
    zoh = discretize(params, dt)
    proto, impl, zoh_step = _observer_code(ct, base, Ks, zoh)
    ctl = config.controller
    l1, l2 = (
        (ctl.lambda1, ctl.lambda2) if ctl is not None else (controller.lambda1, controller.lambda2)
    )
    law = _law_code(ct, controller, dt, gains_from, (l1, l2))
    comment = _comment(summary, gains, Ks, params, phdo)
    header_vals = dict(
        base,
        guard=f"{prefix.upper()}_H",
        summary=comment,
        dt=lit(dt),
        udot_max=lit(udot_max),
        udot_max_comment=_udot_max_comment(summary),
        du_max=lit(udot_max * dt),
        length_unit=params.length_unit,
        input_unit=params.input_unit,
        observer_prototypes="\n".join(proto),
        controller_form=law["controller_form"],
        lambda1=f"{l1:g}",
        lambda2=f"{l2:g}",
    )
    source_vals = dict(
        base,
        stage=params.name or "(unnamed)",
        sha256=config.sha256 or "-",
        **zoh_step,
        **{k: lit(getattr(params, k)) for k in ("alpha", "beta", "gamma", "a1", "a2", "a3")},
        **law,
        length_unit=params.length_unit,
        input_unit=params.input_unit,
        observers="".join(impl),
        hysteresis=hysteresis_source(ct),
    )
    init_dispatch, step_dispatch = _harness_dispatch(prefix, list(_THREE_STATE))
    harness = fill(
        "harness.c.tmpl",
        **base,
        default_observer=observer,
        init_dispatch=init_dispatch,
        step_dispatch=step_dispatch,
    )
    document = {
        "bwdesign": __version__,
        "precision": precision,
        "prefix": prefix,
        "harness_observer": observer,
        "certificate": summary,
        "gains": None if gains is None else list(gains),
        "observers": _observers_document(Ks, phdo),
        "controller": controller.to_dict(),
        "eq12": {"lambda1": l1, "lambda2": l2},
        "model": {
            "F": [list(zoh.F[0]), list(zoh.F[1])],
            "g": [float(zoh.g[0]), float(zoh.g[1])],
            "plant": params.to_dict(),
        },
    }
    out = {
        f"{prefix}.h": fill("header.h.tmpl", **header_vals),
        f"{prefix}.c": fill("source.c.tmpl", **source_vals),
        "harness.c": harness,
        "export.json": dump_json(document) + "\n",
    }
    return out, summary["certified"], summary, document


def _uncertified_reason(
    summary: dict[str, Any], gains: Any, K: Any, phdo: Any, udot_max: float, dt: float
) -> str:
    """Why an export is refused: what is not certified, at which envelope."""
    if gains is None and K is None:
        return "synthesis found no certified gains"
    whys = []
    if summary["tier"] is None:
        whys.append(
            f"no certificate tier holds for these gains at |u'| <= {udot_max:.6g} V/s, "
            f"dt = {dt:g} s"
        )
    if not phdo.certificate.holds:
        whys.append(
            f"the PHDO's lumped error is not certified for its gains ({phdo.origin}) "
            f"at |u'| <= {udot_max:.6g} V/s, dt = {dt:g} s: {phdo.certificate.status}"
        )
    return "; ".join(whys)


def _observer_gains(
    params: Any, gains: Any, K: Any, phdo: Any, dt: float, allow_unbounded: bool
) -> dict[str, list[float]]:
    """The discrete gain ``K`` of every exported observer, as the Python observers run it."""
    observers = {
        name: cls(params, gains, dt, allow_unbounded=allow_unbounded)
        if K is None
        else cls(params, dt=dt, discrete=K, allow_unbounded=allow_unbounded)
        for name, (cls, _) in OBSERVERS.items()
        if name in _THREE_STATE
    }
    observers["phdo"] = (
        DisturbanceHysteresisObserver(params, phdo.gains, dt, allow_unbounded=allow_unbounded)
        if phdo.K is None
        else DisturbanceHysteresisObserver(
            params, dt=dt, discrete=phdo.K, allow_unbounded=allow_unbounded
        )
    )
    return {name: [float(k) for k in obs.K] for name, obs in observers.items()}


def _observer_code(
    ct: CTypes, base: dict[str, str], Ks: dict[str, list[float]], zoh: Any
) -> tuple[list[str], list[str], dict[str, str]]:
    """The observers' prototypes and implementations, and the ZOH step's constants and bodies."""
    lit = ct.literal
    proto, impl = [], []
    for name in _THREE_STATE:
        cls, title = OBSERVERS[name]
        k1, k2, k3 = Ks[name]
        vals = dict(base, obs=name, OBS=name.upper(), title=title)
        proto.append(fill("observer.h.tmpl", **vals))
        x3_next = "hysteresis(s->x[2], s->u_prev, u)" if cls._hysteresis else "s->x[2]"
        impl.append(
            fill("observer.c.tmpl", **vals, k1=lit(k1), k2=lit(k2), k3=lit(k3), x3_next=x3_next)
        )
    zoh_step = _zoh_step(ct, zoh)
    impl.append(
        fill(
            "phdo.c.tmpl",
            **base,
            title=OBSERVERS["phdo"][1],
            **{f"k{i + 1}": lit(k) for i, k in enumerate(Ks["phdo"])},
            propagate_body=zoh_step["propagate_body"],
            correct_body=zoh_step["correct_body"],
        )
    )
    return proto, impl, zoh_step


def _law_code(
    ct: CTypes,
    controller: DiscreteTrackingController,
    dt: float,
    gains_from: str,
    lambdas: tuple[float, float],
) -> dict[str, str]:
    """The controller's values in ``source.c``: gains, saturation, integrator, description."""
    lit = ct.literal
    ck1, ck2 = (float(k) for k in controller.gains)
    limits = controller.u_limits
    saturation = ""
    if limits is not None:
        lo, hi = limits
        if math.isfinite(lo):
            saturation += f"    if (u < {lit(lo)}) {{\n        return {lit(lo)};\n    }}\n"
        if math.isfinite(hi):
            saturation += f"    if (u > {lit(hi)}) {{\n        return {lit(hi)};\n    }}\n"
    integrate = (
        f"    c->q = c->q + {lit(dt)} * (x1 - xd);\n"
        if controller.integral_rate is not None
        else ""
    )
    form = (
        f"lambda1 = {controller.lambda1:g}, lambda2 = {controller.lambda2:g}"
        + (f", integral rate {controller.integral_rate:g}" if controller.integral_rate else "")
        + (", digital tuning" if gains_from == "digital" else "")
    )
    return {
        "ck1": lit(ck1),
        "ck2": lit(ck2),
        "cki": lit(controller.ki),
        "half_dt": lit(0.5 * dt),
        "lambda1_lit": lit(lambdas[0]),
        "lambda2_lit": lit(lambdas[1]),
        "saturation": saturation,
        "integrate": integrate,
        "controller_form": form,
    }


def _observers_document(Ks: dict[str, list[float]], phdo: Any) -> dict[str, Any]:
    """``export.json``'s ``observers``: each observer's ``K``; the PHDO's gains and certificate."""
    return {
        **{name: {"K": Ks[name]} for name in _THREE_STATE},
        "phdo": {
            "K": Ks["phdo"],
            "gains": None if phdo.gains is None else list(phdo.gains),
            "gains_from": phdo.origin,
            "controller_input": "lumped (x1, x2, x3 + d): PREFIX_phdo_lumped",
            "certificate": phdo.certificate.to_dict(),
        },
    }


def _zoh_step(ct: CTypes, zoh) -> dict[str, str]:
    """Constants and bodies of the ZOH predict and the correction, in the precision's best form.

    float64 performs the Python classes' operations in their order (agreement to
    rounding). float32 cannot simply do the same: x1 (about 100 um) carries a
    rounding error of half an ulp (4e-6 um) per sample, and the x3 estimate, seen
    only through the slow drift of x1, turns that into errors of 1e-4 of its
    range. So float32 code keeps x1 as an unevaluated sum ``x[0] + x1_lo``
    (compensated with TwoSum), propagates increments (``F11 - 1`` and ``F22 - 1``
    round with a relative, not an absolute, error) and forms the innovation as
    ``(z - x[0]) - x1_lo``.

    The propagate body reads the hysteresis input of the linear part as ``w``: ``x3``
    for the 3-state observers, the lumped ``x3 + d`` for the PHDO. The PHDO's ``d``
    integrates the innovation and so absorbs, as it is built to, the float32 rounding
    of the constants: a static-gain error of ~1e-7 (about one ulp of x1), i.e. an
    offset of ~1e-5 um in ``d`` that no float32 form of these constants avoids.
    """
    lit = ct.literal
    (f11, f12, f13), (f21, f22, f23) = zoh.F[:2].tolist()
    g1, g2 = float(zoh.g[0]), float(zoh.g[1])
    r = ct.real
    if ct.precision == "float64":
        return {
            "zoh_note": " * Evaluated in the order of the Python classes.",
            "zoh_constants": (
                f"static const {r} F11 = {lit(f11)}, F12 = {lit(f12)}, F13 = {lit(f13)};\n"
                f"static const {r} F21 = {lit(f21)}, F22 = {lit(f22)}, F23 = {lit(f23)};\n"
                f"static const {r} G1 = {lit(g1)}, G2 = {lit(g2)};"
            ),
            "compensation": "",
            "propagate_body": (
                "    const double x1 = s->x[0], x2 = s->x[1];\n"
                "    s->x[0] = F11 * x1 + F12 * x2 + F13 * w + G1 * u;\n"
                "    s->x[1] = F21 * x1 + F22 * x2 + F23 * w + G2 * u;\n"
            ),
            "correct_body": (
                "    const double r = z - s->x[0];\n"
                "    s->x[0] = s->x[0] + k1 * r;\n"
                "    s->x[1] = s->x[1] + k2 * r;\n"
                "    s->x[2] = s->x[2] + k3 * r;\n"
            ),
        }
    return {
        "zoh_note": " * Increment form: D11 = F11 - 1, D22 = F22 - 1 keep full float32 precision.",
        "zoh_constants": (
            f"static const {r} D11 = {lit(f11 - 1.0)}, F12 = {lit(f12)}, F13 = {lit(f13)};\n"
            f"static const {r} F21 = {lit(f21)}, D22 = {lit(f22 - 1.0)}, F23 = {lit(f23)};\n"
            f"static const {r} G1 = {lit(g1)}, G2 = {lit(g2)};"
        ),
        "compensation": (
            "/* hi + lo = a + b exactly (TwoSum; needs IEEE arithmetic: no -ffast-math) */\n"
            "static void two_sum(float a, float b, float *hi, float *lo)\n"
            "{\n"
            "    const float s = a + b;\n"
            "    const float bb = s - a;\n"
            "    *lo = (a - (s - bb)) + (b - bb);\n"
            "    *hi = s;\n"
            "}\n\n"
        ),
        "propagate_body": (
            "    const float x1 = s->x[0], lo = s->x1_lo, x2 = s->x[1];\n"
            "    const float d1 = D11 * x1 + F12 * x2 + F13 * w + G1 * u + D11 * lo;\n"
            "    s->x[1] = x2 + (F21 * x1 + D22 * x2 + F23 * w + G2 * u + F21 * lo);\n"
            "    two_sum(x1, lo + d1, &s->x[0], &s->x1_lo);\n"
        ),
        "correct_body": (
            "    const float r = (z - s->x[0]) - s->x1_lo;\n"
            "    two_sum(s->x[0], s->x1_lo + k1 * r, &s->x[0], &s->x1_lo);\n"
            "    s->x[1] = s->x[1] + k2 * r;\n"
            "    s->x[2] = s->x[2] + k3 * r;\n"
        ),
    }


def _harness_dispatch(prefix: str, names: list[str]) -> tuple[str, str]:
    """The 3-state observers' init and step in the harness (the PHDO has its own loops)."""
    modes = [*names, "phdo", "phdo-loop", "controller", "eq12"]
    init = []
    step = [
        "        {",
        "            char *zend;",
        "            const double z = strtod(comma + 1, &zend);",
        "            const int has_z = zend != comma + 1;",
    ]
    for i, name in enumerate(names):
        kw = "if" if i == 0 else "} else if"
        init += [f'    {kw} (strcmp(name, "{name}") == 0) {{', f"        {prefix}_{name}_init(&s);"]
        step += [
            f'            {kw} (strcmp(name, "{name}") == 0) {{',
            f"                {prefix}_{name}_predict(&s, ({prefix}_real)u);",
            "                if (has_z) {",
            f"                    {prefix}_{name}_update(&s, ({prefix}_real)z);",
            "                }",
        ]
    init += [
        "    } else {",
        f'        fprintf(stderr, "harness: unknown mode %s ({", ".join(modes)})\\n", name);',
        "        return 2;",
        "    }",
    ]
    step += ["            }", "        }"]
    return "\n".join(init), "\n".join(step)


def export_c(
    config: StageConfig,
    out_dir: str | Path,
    *,
    precision: str = "float64",
    observer: str = "phso",
    prefix: str = "bw",
    gains_from: str = "config",
    allow_uncertified: bool = False,
    allow_unbounded: bool = False,
    force: bool = False,
) -> CExport:
    """Write the C library of the certified observers and controller into ``out_dir``.

    Parameters
    ----------
    config : StageConfig
        Needs [plant], [sampling] dt, [envelope], [controller] and [observer]
        gains (or ``gains_from="synthesize"`` / ``"digital"``).
    out_dir : path
        Output directory (written through the package's output layer).
    precision : {"float64", "float32"}
        Arithmetic of the generated code.
    observer : {"phso", "eso", "phdo"}
        The observer the harness runs by default (the library carries all three).
    prefix : str
        C identifier prefixed to every exported name.
    gains_from : {"config", "synthesize", "digital"}
        The config's [observer] gains; gains synthesised for the config's
        envelope (as ``bwdesign report`` does); or the digital tuning's gains
        and controller (:func:`bwdesign.digital_tuning`). The PHDO's gains follow from
        each source as :func:`_phdo_gains` says (``export.json``'s
        ``observers.phdo.gains_from`` records which).
    allow_uncertified : bool
        Export gains that no certificate holds for: no tier for the PHSO/ESO gains, or
        no lumped-error certificate (:func:`bwdesign.certify_disturbance`) for the
        PHDO's (the header says so).
    force : bool
        Write into a directory holding files bwdesign did not write (they are kept).

    Returns
    -------
    CExport

    Raises
    ------
    NotCertifiedError
        No tier certifies the PHSO/ESO gains, or the PHDO's lumped error is not
        certified (and ``allow_uncertified`` is False).
    ConfigError, InputError, UnboundedModelError
        Bad configuration or options; nothing is written.
    """
    target = prepare_directory(out_dir, command="export-c", force=force, what="--out")
    sources, certified, summary, document = c_sources(
        config,
        precision=precision,
        observer=observer,
        prefix=prefix,
        gains_from=gains_from,
        allow_uncertified=allow_uncertified,
        allow_unbounded=allow_unbounded,
    )
    with target.stage() as stage:
        for name, text in sources.items():
            stage.write_text(name, text)
    return CExport(
        out_dir=target.path,
        files=tuple(sources),
        certified=certified,
        summary=summary,
        document=document,
    )
