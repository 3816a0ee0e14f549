"""The config reader (``realize.config``): types, bounds, choices, unknown keys, nesting, cross checks."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from realize.config import ConfigError, Settings, setting


@dataclass
class Inner(Settings):
    config_key = "outer.inner"
    radius: float = setting(0.5, gt=0)
    center: tuple[float, float] = (0.0, 0.0)


@dataclass
class Outer(Settings):
    config_key = "outer"
    n: int = setting(4, ge=1)
    mode: str = setting("a", choices=("a", "b"))
    share: float = setting(0.0, ge=0, lt=1)
    limit: int | None = setting(None, ge=0)
    flag: bool = False
    inner: Inner = setting(default_factory=Inner)

    def check(self, where: str) -> None:
        if self.mode == "b" and self.n < 2:
            raise ConfigError(f"{where}.n = {self.n} is invalid: mode 'b' needs >= 2")


def test_defaults_and_conversion() -> None:
    o = Outer.from_mapping({"n": 8.0, "share": 0, "inner": {"center": [1, 2]}})
    assert o.n == 8 and isinstance(o.n, int) and o.share == 0.0 and isinstance(o.share, float)
    assert o.inner.center == (1.0, 2.0) and o.inner.radius == 0.5
    assert Outer.from_mapping(None) == Outer()


@pytest.mark.parametrize(
    "d, needle",
    [
        ({"n": 0}, "outer.n = 0 is invalid: must be >= 1"),
        ({"n": 1.5}, "outer.n = 1.5 is invalid: must be an integer"),
        ({"n": True}, "outer.n = True is invalid: must be an integer"),
        ({"mode": "c"}, "outer.mode = 'c' is invalid: allowed ['a', 'b']"),
        ({"share": 1.0}, "outer.share = 1.0 is invalid: must be < 1"),
        ({"share": float("nan")}, "outer.share = nan is invalid: must be a finite number"),
        ({"limit": -1}, "outer.limit = -1 is invalid: must be >= 0"),
        ({"flag": "yes"}, "outer.flag = 'yes' is invalid: must be true or false"),
        ({"inner": {"radius": -0.1}}, "outer.inner.radius = -0.1 is invalid: must be > 0"),
        ({"inner": {"center": [1]}}, "outer.inner.center = [1] is invalid: must be a list of 2 values"),
        ({"inner": {"radus": 1}}, "outer.inner: unknown key(s) ['radus']"),
        ({"nn": 1}, "outer: unknown key(s) ['nn']; allowed: ['flag', 'inner', 'limit', 'mode', 'n', 'share']"),
        ({"mode": "b", "n": 1}, "outer.n = 1 is invalid: mode 'b' needs >= 2"),
    ],
)
def test_errors_name_key_value_and_rule(d: dict, needle: str) -> None:
    with pytest.raises(ConfigError) as e:
        Outer.from_mapping(d)
    assert needle in str(e.value)
    assert "\n" not in str(e.value)


def test_where_prefix_and_direct_construction() -> None:
    with pytest.raises(ConfigError, match=r"^task:outer\.n = 0 "):
        Outer.from_mapping({"n": 0}, "task:outer")
    with pytest.raises(ConfigError, match=r"^outer\.n = 0 "):
        Outer(n=0)
    with pytest.raises(ConfigError, match="must be a mapping"):
        Outer.from_mapping([1, 2])
    assert isinstance(ConfigError("x"), ValueError)


@pytest.mark.parametrize("override, key", [
    ("robot.fabric_exclude=[finger_r,no_such_sphere]", "robot.fabric_exclude"),
    ("controller.fabric.collision_exclude=[no_such_sphere]", "controller.fabric.collision_exclude"),
    ("robot=mobile_panda", None),  # the default exclusions are the robot's own
])
def test_fabric_exclusions_name_spheres_of_the_robot(override: str, key: str | None) -> None:
    """The spheres left out of the fabric's box leaves are checked against the robot's sphere
    file at the config edge, naming the key they came from."""
    from helpers import compose_config
    from realize.spec.run_spec import build_run_spec

    if key is None:
        assert build_run_spec(compose_config(override)).robot.name == "mobile_panda"
        return
    with pytest.raises(ConfigError, match=rf"^{key} = .*unknown spheres \['no_such_sphere'\] of robot 'fetch_omni'"):
        build_run_spec(compose_config(override))
