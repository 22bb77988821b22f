"""A numeric setting's bounds are declared on its field (estimation.limits) and hold."""

from __future__ import annotations

import dataclasses
import math
import typing

import pytest

from estimation.errors import ConfigError
from estimation.limits import NON_NEGATIVE, POSITIVE, Limit, Limited, limited
from landing_env.config import DeckLandingConfig


def _config_classes(cls: type, seen: dict[str, type]) -> dict[str, type]:
    seen[cls.__name__] = cls
    hints = typing.get_type_hints(cls)
    for item in dataclasses.fields(cls):
        if dataclasses.is_dataclass(hints[item.name]):
            _config_classes(hints[item.name], seen)
    return seen


CLASSES = _config_classes(DeckLandingConfig, {})
DECLARED = [
    (name, item.name, item.metadata["limit"])
    for name, cls in CLASSES.items()
    for item in dataclasses.fields(cls)
    if "limit" in item.metadata
]


def _outside(limit: Limit) -> list[float]:
    values = []
    if limit.low is not None:
        values.append(limit.low if not limit.low_inclusive else limit.low - 1)
    if limit.high is not None:
        values.append(limit.high if not limit.high_inclusive else limit.high + 1)
    return values


@pytest.mark.parametrize(
    ("cls", "field", "limit"), DECLARED, ids=[f"{c}.{f}" for c, f, _ in DECLARED]
)
def test_a_config_field_refuses_a_value_just_outside_its_declared_limit_naming_it(
    cls: str, field: str, limit: Limit
) -> None:
    for value in _outside(limit):
        with pytest.raises(ConfigError) as error:
            CLASSES[cls](**{field: value})
        assert error.value.key == field, str(error.value)


def test_the_config_tree_declares_its_limits_on_its_fields() -> None:
    assert len(DECLARED) >= 100


@dataclasses.dataclass
class _Rig(Limited):
    speed_mps: float = limited(1.0, POSITIVE)
    count: int = limited(3, Limit(1, 10))
    margin_m: float = limited(0.0, NON_NEGATIVE)
    free: float = -5.0
    #: optional: None leaves it unset
    gap_m: float | None = limited(None, POSITIVE)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"speed_mps": 0.0}, "speed_mps: 0.0 is out of range; allowed (0.0, inf]"),
        ({"count": 11}, "count: 11 is out of range; allowed [1, 10]"),
        ({"margin_m": -0.5}, "margin_m: -0.5 is out of range; allowed [0.0, inf]"),
    ],
)
def test_require_limits_refuses_the_field_outside_its_limit_with_the_range(
    changes: dict, message: str
) -> None:
    with pytest.raises(ConfigError) as error:
        _Rig(**changes)
    assert str(error.value) == message


def test_fields_without_a_limit_and_values_on_a_bound_are_accepted() -> None:
    rig = _Rig(speed_mps=1e-9, count=10, margin_m=0.0, free=-1e9)
    assert (rig.count, rig.margin_m, rig.free) == (10, 0.0, -1e9)


def test_an_optional_field_may_be_left_none_and_a_value_given_to_it_is_checked() -> None:
    assert _Rig().gap_m is None and _Rig(gap_m=0.5).gap_m == 0.5
    with pytest.raises(ConfigError) as error:
        _Rig(gap_m=0.0)
    assert str(error.value) == "gap_m: 0.0 is out of range; allowed (0.0, inf]"


def test_the_loaders_table_is_the_physical_range_each_field_declares() -> None:
    from landing_env.config_limits import LIMITS, physical_limits
    from landing_env.sensors.camera_config import CameraConfig

    assert LIMITS == physical_limits(DeckLandingConfig)
    fx = next(item for item in dataclasses.fields(CameraConfig) if item.name == "fx")
    assert LIMITS["camera.fx"] is fx.metadata["physical"]
    assert len(LIMITS) >= 190


def test_a_physical_range_is_checked_on_load_and_a_field_limit_always() -> None:
    from landing_env.config import load_config
    from landing_env.sensors.camera_config import CameraConfig

    assert CameraConfig(fx=2e5).fx == 2e5  # beyond the physical range, still computable
    with pytest.raises(ConfigError) as error:
        load_config("default", overrides={"camera.fx": 2e5})
    assert error.value.key == "camera.fx" and "100000.0]" in str(error.value)
    for build in (lambda: CameraConfig(fx=0.0), lambda: load_config("default", camera={"fx": 0.0})):
        with pytest.raises(ConfigError, match=r"fx: 0\.0 is out of range; allowed \(0\.0,"):
            build()


def test_the_named_limits_bound_zero_to_high_or_minus_to_plus_bound_with_their_note() -> None:
    assert Limit.positive(5.0, "metres") == Limit(0.0, 5.0, low_inclusive=False, note="metres")
    assert Limit.non_negative(5.0, "metres") == Limit(0.0, 5.0, note="metres")
    assert Limit.symmetric(2.0, "radians") == Limit(-2.0, 2.0, note="radians")
    for made in (Limit.positive(5.0), Limit.non_negative(5.0), Limit.symmetric(2.0)):
        assert made.note == ""
    with pytest.raises(ConfigError, match=r"^k: 0\.0 is out of range; allowed \(0\.0, 5\.0\]$"):
        Limit.positive(5.0).check("k", 0.0)
    Limit.non_negative(5.0).check("k", 0.0)
    with pytest.raises(ConfigError, match=r"^k: -2\.5 is out of range; allowed \[-2\.0, 2\.0\]$"):
        Limit.symmetric(2.0).check("k", -2.5)


def test_infinity_passes_only_a_limit_that_allows_it_and_only_plus_infinity() -> None:
    bounded = Limit(0.0, 10.0)
    unbounded = Limit(0.0, 10.0, allow_inf=True)
    unbounded.check("k", math.inf)
    for value in (math.inf, -math.inf, 11.0):
        with pytest.raises(ConfigError) as error:
            bounded.check("k", value)
        assert error.value.key == "k"
    for value in (-math.inf, 11.0, -1.0):
        with pytest.raises(ConfigError) as error:
            unbounded.check("k", value)
        assert error.value.key == "k"


def test_a_limited_field_keeps_its_default_its_factory_and_only_the_bounds_given() -> None:
    physical = Limit.positive(9.0, "datasheet")

    @dataclasses.dataclass
    class Rig(Limited):
        speed_mps: float = limited(1.5, POSITIVE, physical=physical)
        margin_m: float = limited(0.25, NON_NEGATIVE)
        offsets_m: tuple[float, ...] = limited(default_factory=lambda: (0.5,), physical=physical)
        free: float = limited(-3.0)

    items = {item.name: item for item in dataclasses.fields(Rig)}
    assert dict(items["speed_mps"].metadata) == {"limit": POSITIVE, "physical": physical}
    assert dict(items["margin_m"].metadata) == {"limit": NON_NEGATIVE}
    assert dict(items["offsets_m"].metadata) == {"physical": physical}
    assert dict(items["free"].metadata) == {}
    rig = Rig()
    assert (rig.speed_mps, rig.margin_m, rig.offsets_m, rig.free) == (1.5, 0.25, (0.5,), -3.0)
    with pytest.raises(ConfigError) as error:
        Rig(margin_m=-0.5)
    assert str(error.value) == "margin_m: -0.5 is out of range; allowed [0.0, inf]"
