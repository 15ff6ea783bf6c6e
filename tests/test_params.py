import math

import pytest

from bwdesign import (
    BoucWenParams,
    ConfigError,
    ParameterError,
    UnboundedModelError,
    load_plant,
    preset,
)
from bwdesign.model.params import require_bounded

GOOD = dict(a1=159827.5, a2=713.8, a3=222665.02, alpha=0.4795, beta=0.3762, gamma=0.0378)


@pytest.mark.parametrize(
    "field, value, match",
    [
        ("a1", 0.0, "a1 = k/m must be > 0"),
        ("a1", -1.0, "a1 = k/m must be > 0"),
        ("a2", -0.1, "a2 = b/m must be >= 0"),
        ("a3", 0.0, "a3 = k d/m must be non-zero"),
        ("alpha", 0.0, "alpha must be > 0"),
        ("alpha", -2.0, "alpha must be > 0"),
        ("beta", math.nan, "beta must be finite"),
        ("gamma", math.inf, "gamma must be finite"),
        ("a1", "1e5", "a1 must be a number"),
        ("a2", None, "a2 must be a number"),
        ("a3", True, "a3 must be a number"),
    ],
    ids=lambda v: repr(v),
)
def test_validation_names_the_field(field, value, match):
    kwargs = dict(GOOD, **{field: value})
    with pytest.raises(ParameterError, match=match) as info:
        BoucWenParams(**kwargs)
    assert info.value.field == field
    assert isinstance(info.value, ValueError)


def test_keyword_only():
    with pytest.raises(TypeError):
        BoucWenParams(1.0, 2.0, 3.0, 1.0, 1.0, 0.0)  # type: ignore[misc]


def test_from_physical_maps_to_model_form():
    p = BoucWenParams.from_physical(
        m=2.0, b=10.0, k=4.0e5, d=1.5, alpha0=0.3, beta=0.2, gamma=0.1, name="toy"
    )
    assert p.a1 == pytest.approx(2.0e5)
    assert p.a2 == pytest.approx(5.0)
    assert p.a3 == pytest.approx(4.0e5 * 1.5 / 2.0)
    assert p.alpha == pytest.approx(0.45)
    assert p.physical is not None and p.physical.m == 2.0


@pytest.mark.parametrize("field", ["m", "k"])
def test_from_physical_rejects_nonpositive(field):
    kw = dict(m=2.0, b=10.0, k=4.0e5, d=1.5, alpha0=0.3, beta=0.2, gamma=0.1)
    kw[field] = 0.0
    with pytest.raises(ParameterError, match=f"{field} must be > 0"):
        BoucWenParams.from_physical(**kw)


@pytest.mark.parametrize(
    "name", ["paper_experiment", "paper_simulation", "paper_simulation_corrected"]
)
def test_toml_round_trip(tmp_path, name):
    p = preset(name)
    f = tmp_path / "plant.toml"
    f.write_text(p.to_toml())
    q = load_plant(f)
    assert q == p
    assert q.name == p.name


def test_toml_round_trip_physical(tmp_path):
    p = BoucWenParams.from_physical(
        m=2.0, b=10.0, k=4.0e5, d=1.5, alpha0=0.3, beta=0.2, gamma=0.1, name="phys"
    )
    f = tmp_path / "phys.toml"
    f.write_text(p.to_toml())
    q = load_plant(f)
    assert q == p and q.physical == p.physical


def test_presets():
    e = preset("paper_experiment")
    assert (e.a1, e.a2, e.a3) == (159827.5, 713.8, 222665.02)
    assert e.bounded_class().bounded
    s = preset("paper_simulation")
    assert s.beta == -1.3567
    v = s.bounded_class()
    assert not v.bounded and "beta + gamma" in v.reason and math.isinf(v.h_max)
    c = preset("paper_simulation_corrected")
    assert c.beta == 1.3567 and c.bounded_class().bounded
    assert c.bounded_class().h_max == pytest.approx(4.6325 / (1.3567 + 0.4677))


def test_bounded_class_second_condition():
    p = BoucWenParams(**dict(GOOD, beta=0.1, gamma=0.3))  # beta + gamma > 0, beta - gamma < 0
    v = p.bounded_class()
    assert not v.bounded and "beta - gamma" in v.reason


def test_require_bounded():
    with pytest.raises(UnboundedModelError, match="allow_unbounded"):
        require_bounded(preset("paper_simulation"))
    require_bounded(preset("paper_simulation"), allow_unbounded=True)
    require_bounded(preset("paper_experiment"))


def test_unknown_preset():
    with pytest.raises(ConfigError, match="unknown plant preset 'nope'"):
        load_plant("nope")


def test_params_are_hashable_and_frozen():
    p = preset("paper_experiment")
    assert hash(p) == hash(p.replace(name="paper_experiment"))
    with pytest.raises(AttributeError):
        p.a1 = 1.0  # type: ignore[misc]
