"""The uncertainty box: one type from a file, text or Python; its bounds; its one check."""

from __future__ import annotations

import itertools
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

from bwdesign import ConfigError, InputError, ParameterError, UncertaintyBox, load_config, preset
from bwdesign.model.params import MODEL_FIELDS

P = preset("paper_experiment")  # a1 159827.5, a3 222665.02, alpha 0.4795, beta 0.3762, gamma 0.0378


# -- from a stage file ---------------------------------------------------------------


def test_uncertainty_box_round_trip_and_geometry():
    box = UncertaintyBox.from_dict(
        {"source": "specified", "level": 0.9, "a1": {"rel": 0.02}, "alpha": {"abs": 0.01}}
    )
    again = UncertaintyBox.from_dict(tomllib.loads(box.to_toml())["uncertainty"])
    assert again == box
    assert box.half_width("a1", P) == pytest.approx(0.02 * P.a1)
    assert box.half_width("beta", P) == 0.0
    assert box.bounds(P)["alpha"] == pytest.approx((P.alpha - 0.01, P.alpha + 0.01))
    verts = box.vertices(P)
    assert len(verts) == 4
    assert sorted({v.a1 for v in verts}) == pytest.approx([0.98 * P.a1, 1.02 * P.a1])
    samples = box.sample(P, np.random.default_rng(0), 50)
    assert all(abs(s.a1 - P.a1) <= 0.02 * P.a1 and s.beta == P.beta for s in samples)
    b = box.bounds(P)
    assert box.check(P) == {"a1": b["a1"], "alpha": b["alpha"]}


@pytest.mark.parametrize(
    "table,match",
    [
        ({"a1": {"rel": 0.1, "abs": 1.0}}, "exactly one of rel"),
        ({"a1": 0.1}, "must be a table"),
        ({"a4": {"rel": 0.1}}, "unknown key"),
        ({"a1": {"rel": -0.1}}, ">= 0"),
        ({"a1": {"rel": "x"}}, "must be a number"),
        ({"source": "guessed"}, "source must be one of"),
        ({"level": 1.5}, r"level must be a number in \(0, 1\)"),
    ],
    ids=["both", "not_table", "unknown", "negative", "string", "source", "level"],
)
def test_uncertainty_strict_keys(table, match):
    with pytest.raises(ConfigError, match=match):
        UncertaintyBox.from_dict(table)


def test_undetermined_box_refuses_vertices(tmp_path):
    box = UncertaintyBox.from_dict({"a1": {"rel": math.inf}, "alpha": {"abs": 0.01}})
    assert box.undetermined() == ("a1",)
    assert box.bounds(P)["a1"] == (-math.inf, math.inf)
    for call in (box.check, box.vertices, lambda p: box.sample(p, np.random.default_rng(0), 3)):
        with pytest.raises(ParameterError, match="a1 not determined") as info:
            call(P)
        assert info.value.field == "a1"
    cfg = tmp_path / "s.toml"
    cfg.write_text(P.to_toml() + "\n" + box.to_toml())
    assert load_config(cfg).uncertainty == box
    cfg.write_text(P.to_toml())
    assert load_config(cfg).uncertainty is None


# -- from text -----------------------------------------------------------------------


def test_parse_is_the_same_box_as_the_file():
    text = UncertaintyBox.parse(" alpha = 0.01 , a1=2%,")
    table = UncertaintyBox.from_dict({"a1": {"rel": 0.02}, "alpha": {"abs": 0.01}})
    assert text == table and list(text.widths) == ["a1", "alpha"]  # one order: a1 ... gamma
    assert text.source is None and text.level is None
    assert UncertaintyBox.parse("gamma=10%,beta=1e-3").to_toml() == (
        "[uncertainty]\nbeta = { abs = 0.001 }\ngamma = { rel = 0.1 }\n"
    )
    every = UncertaintyBox.parse(",".join(f"{n}=3%" for n in MODEL_FIELDS))
    assert every.widths == {n: ("rel", 0.03) for n in MODEL_FIELDS}


#: (text, part of the message); every one an InputError naming the option
PARSE_ERRORS = [
    ("zeta=2%", "expected NAME=WIDTH with NAME in a1, a2, a3, alpha, beta, gamma"),
    ("a1", "got 'a1'"),
    ("a1=x", "a1 half-width must be a number, got 'x'"),
    ("a1=2%%", "a1 half-width (%) must be a number, got '2%'"),
    ("a1=-2%", "a1 half-width (%) = -2 is outside the supported range [0, inf)"),
    ("alpha=-0.01", "alpha half-width = -0.01 is outside the supported range [0, inf)"),
    ("a1=inf", "a1 half-width must be finite, got inf"),
    ("a1=nan%", "a1 half-width (%) must be finite, got nan"),
    ("a1=2%,a1=3%", "a1 given twice (2% and 3%); give each parameter once"),
    ("alpha=0.01,alpha=1%", "alpha given twice (0.01 and 1%)"),
    ("", "no parameter given"),
    (" , ,", "no parameter given"),
]


@pytest.mark.parametrize("text, message", PARSE_ERRORS, ids=[t or "empty" for t, _ in PARSE_ERRORS])
def test_parse_errors_are_input_errors(text, message):
    with pytest.raises(InputError) as info:
        UncertaintyBox.parse(text, name="--uncertainty")
    assert str(info.value).startswith("--uncertainty: ") and message in str(info.value)
    assert not isinstance(info.value, ConfigError)


def test_parse_refuses_what_is_not_text():
    with pytest.raises(InputError, match="uncertainty: expected text"):
        UncertaintyBox.parse({"a1": 0.02})


def test_the_constructor_raises_input_errors_the_file_config_errors():
    """One rule: a stage file's table -> ConfigError; Python (and text) -> InputError."""
    for widths, message in (
        ({"zeta": ("rel", 0.1)}, "unknown parameter 'zeta'"),
        ({"a1": ("rel", -0.1)}, "a1.rel must be >= 0"),
        ({"a1": ("pct", 0.1)}, "kind must be rel or abs"),
        ({"a1": 0.1}, 'expected ("rel" | "abs", half-width)'),
        ([("a1", 0.1)], "must be a mapping"),
    ):
        with pytest.raises(InputError) as info:
            UncertaintyBox(widths=widths)
        assert message in str(info.value) and not isinstance(info.value, ConfigError)
    with pytest.raises(InputError, match="level must be a number in"):
        UncertaintyBox(level=2.0)
    with pytest.raises(ConfigError, match=r"\[uncertainty\] a1.rel must be >= 0"):
        UncertaintyBox.from_dict({"a1": {"rel": -0.1}})


# -- bounds and the one check ----------------------------------------------------------


def test_bounds_and_describe():
    box = UncertaintyBox.parse("a1=2%,alpha=0.01")
    b = box.bounds(P)
    assert list(b) == list(MODEL_FIELDS)
    assert b["a1"] == (P.a1 - 0.02 * P.a1, P.a1 + 0.02 * P.a1) and b["beta"] == (P.beta, P.beta)
    assert box.describe(P) == (
        f"a1 in [{b['a1'][0]:.6g}, {b['a1'][1]:.6g}], "
        f"alpha in [{b['alpha'][0]:.6g}, {b['alpha'][1]:.6g}]"
    )
    neg = P.replace(a3=-P.a3)  # a relative width is of |nominal|: the same box mirrored
    lo, hi = UncertaintyBox.parse("a3=10%").bounds(neg)["a3"]
    assert (lo, hi) == pytest.approx((-1.1 * P.a3, -0.9 * P.a3))


#: (box, what the check says, the parameter it names)
CHECK_ERRORS = [
    ("beta=95%", "leaves the bounded class", "beta"),
    ("gamma=0.5", "beta + gamma > 0 is", "gamma"),
    ("a3=150%", "lets a3 reach 0", "a3"),
    ("a1=200%", "lets a1 reach", "a1"),
    ("alpha=1", "lets alpha reach", "alpha"),
    ("beta=2e6", "beta = -2e+06 is outside the supported range", "beta"),
    ("a2=1e10", "lets a2 reach", "a2"),
]


@pytest.mark.parametrize("text, message, field", CHECK_ERRORS, ids=[c[0] for c in CHECK_ERRORS])
def test_check_is_one_parameter_error(text, message, field):
    box = UncertaintyBox.parse(text)
    with pytest.raises(ParameterError, match="uncertainty box") as info:
        box.check(P)
    assert message in str(info.value) and info.value.field == field


def test_check_names_the_corner_outside_the_class():
    box = UncertaintyBox.from_dict({"gamma": {"abs": 0.5}})
    lo = P.gamma - 0.5
    with pytest.raises(ParameterError) as info:
        box.check(P)
    assert f"gamma = {lo:.6g}, beta + gamma > 0 is {P.beta + lo:.6g}" in str(info.value)
    # without the class: the corners are valid models (a certificate may say "no" for them)
    assert box.check(P, bounded=False) == {"gamma": (lo, P.gamma + 0.5)}
    assert [v.bounded_class().bounded for v in box.vertices(P)] == [False, False]


def test_check_accepts_what_the_old_sweep_check_refused_wrongly():
    """a2 may reach 0 (a2 >= 0 is a valid model); a negative a3 keeps its sign."""
    assert UncertaintyBox.parse("a2=100%").check(P)["a2"] == (0.0, 2 * P.a2)
    neg = P.replace(a3=-P.a3)
    assert UncertaintyBox.parse("a3=50%").check(neg)["a3"] == (-1.5 * P.a3, -0.5 * P.a3)
    assert UncertaintyBox().check(P) == {}  # an empty box: every parameter exact


def test_check_passes_exactly_when_every_corner_is_a_bounded_model():
    """The corners decide: for seeded random boxes, check() agrees with building every corner."""
    rng = np.random.default_rng(25)
    outcomes = set()
    for _ in range(60):
        names = [n for n in MODEL_FIELDS if rng.random() < 0.5] or ["beta"]
        box = UncertaintyBox(widths={n: ("rel", float(rng.uniform(0, 1.6))) for n in names})
        b = box.bounds(P)
        try:
            corners = [
                P.replace(**dict(zip(names, ends, strict=True)))
                for ends in itertools.product(*[b[n] for n in names])
            ]
            usable = all(
                c.bounded_class().bounded and not (b["a3"][0] <= 0 <= b["a3"][1]) for c in corners
            )
        except ParameterError:
            usable = False
        try:
            box.check(P)
            ok = True
        except ParameterError:
            ok = False
        assert ok is usable, box
        outcomes.add(ok)
    assert outcomes == {True, False}


# -- the unexplained-behaviour bound (issue 26, Build 3) ----------------------------


def test_disturbance_bound_from_a_stage_file(tmp_path):
    from bwdesign import DisturbanceBound, load_config

    text = Path("configs/paper_experiment.toml").read_text()
    text += (
        "\n[uncertainty]\na3 = { rel = 0.02 }\n\n[uncertainty.disturbance]\n"
        'input_max = 0.35\nrate_max = 2.0\nsource = "identified"\n'
    )
    f = tmp_path / "stage.toml"
    f.write_text(text)
    cfg = load_config(f)
    assert cfg.disturbance == DisturbanceBound(0.35, 2.0, "identified")
    assert not cfg.disturbance.none and DisturbanceBound(0, 0).none
    assert DisturbanceBound.from_dict(cfg.disturbance.to_dict()) == cfg.disturbance
    assert "input_max = 0.35" in cfg.disturbance.to_toml()
    assert load_config("configs/paper_experiment.toml").disturbance is None


@pytest.mark.parametrize(
    "table, match",
    [
        ({"input_max": -1.0, "rate_max": 0.0}, r"input_max = -1 is outside"),
        ({"input_max": float("inf"), "rate_max": 0.0}, "must be finite"),
        ({"input_max": "1", "rate_max": 0.0}, "must be a number"),
        ({"input_max": 1.0}, "missing rate_max"),
        ({"input_max": 1.0, "rate_max": 1.0, "amplitude": 1}, "unknown key"),
        ({"input_max": 1.0, "rate_max": 1.0, "source": "guessed"}, "source must be one of"),
    ],
)
def test_a_bad_disturbance_table_is_a_config_error(table, match):
    from bwdesign.model.uncertainty import DisturbanceBound

    with pytest.raises(ConfigError, match=match) as err:
        DisturbanceBound.from_dict(table)
    assert "[uncertainty.disturbance]" in str(err.value)
