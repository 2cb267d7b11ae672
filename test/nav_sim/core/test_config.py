"""The one conversion of a setting to its declared type, and who uses it (issue 10, section 3)."""

from __future__ import annotations

import math

import pytest

from nav_sim.core.config import SimConfig, convert, validate_seed
from nav_sim.errors import ConfigError, ScenarioError
from nav_sim.ros.process import ros_args, typed_params
from nav_sim.ros.settings import PARAMETER_TYPES, realtime_period_ns

CONVERTED = [
    (int, 4, 4), (int, 4.0, 4), (int, '4', 4), (int, '4.0', 4), (int, ' 12 ', 12),
    (int, '1e3', 1000), (int, -3, -3),
    (float, 90, 90.0), (float, '0.016', 0.016), (float, '90', 90.0), (float, 1.5, 1.5),
    (bool, True, True), (bool, 'false', False), (bool, 'TRUE', True), (bool, ' true ', True),
    (str, 'arena.xml', 'arena.xml'), (str, '', ''),
]
REFUSED = [
    (int, 3.7), (int, '3.7'), (int, 'four'), (int, True), (int, math.nan), (int, math.inf),
    (int, '1e400'), (int, None), (int, [1]),
    (float, False), (float, 'fast'), (float, 10**400), (float, None), (float, [1.0]),
    (bool, 'yes'), (bool, 'no'), (bool, 1), (bool, 0), (bool, '1'), (bool, 1.0),
    (str, 5), (str, 1.5), (str, True), (str, None),
]


@pytest.mark.parametrize(('kind', 'value', 'expected'), CONVERTED)
def test_convert_takes_what_converts_without_loss(kind, value, expected):
    result = convert('x', kind, value)
    assert result == expected and type(result) is kind


@pytest.mark.parametrize(('kind', 'value'), REFUSED)
def test_convert_refuses_the_rest_naming_the_setting_and_the_type(kind, value):
    word = {int: 'an integer', float: 'a number', bool: 'true or false', str: 'a string'}[kind]
    with pytest.raises(ConfigError, match=f'^sim_dt takes {word}, got '):
        convert('sim_dt', kind, value)


@pytest.mark.parametrize(('name', 'value'), [
    ('action_repeat', 3.7), ('action_repeat', '4.0'), ('action_repeat', '3.7'),
    ('camera_hfov_deg', 90), ('camera_hfov_deg', '90'), ('sim_dt', 'fast'), ('world', 5),
    ('train_bank_seed', True), ('camera_width', 128.0),
])
def test_from_dict_and_typed_params_agree(name, value):
    try:
        expected = convert(name, PARAMETER_TYPES[name], value)
    except ConfigError:
        with pytest.raises(ConfigError, match=name):
            SimConfig.from_dict({name: value})
        with pytest.raises(ConfigError, match=name):
            typed_params({name: value})
        return
    config = SimConfig.from_dict({name: value})
    assert getattr(config, name) == expected and type(getattr(config, name)) is type(expected)
    assert typed_params({name: value}) == {name: expected}


def test_from_dict_no_longer_truncates_an_int():
    with pytest.raises(ConfigError, match='action_repeat takes an integer, got 3.7'):
        SimConfig.from_dict({'action_repeat': 3.7})  # was silently 3


def test_typed_params_rejects_unknown_names_and_integers_beyond_64_bits():
    with pytest.raises(ConfigError, match="unknown sim_node parameter.*'sim_dtt'"):
        typed_params({'sim_dtt': 0.01})
    with pytest.raises(ConfigError, match='seed must be in'):
        typed_params({'seed': 2**64})
    assert ros_args(params={'camera_hfov_deg': 90, 'publish_clock': 'false'}) == [
        '--ros-args', '-p', 'camera_hfov_deg:=90.0', '-p', 'publish_clock:=false']


def test_realtime_period_must_fit_a_ros_timer():
    ctrl_dt = SimConfig().ctrl_dt
    assert realtime_period_ns(ctrl_dt, 1.0) == 512_000_000
    assert realtime_period_ns(ctrl_dt, 4.0) == 128_000_000
    assert realtime_period_ns(ctrl_dt, 5.56e-11) < 2**63  # the bounds the message gives work
    assert realtime_period_ns(ctrl_dt, 5.12e8) == 1
    for rate in (1e-12, 1e-300, 1e9, 1e300, 0.0, -1.0, math.inf, math.nan):
        with pytest.raises(ConfigError, match=r'realtime_rate must be in \[5.56e-11, 5.12e\+08\]'):
            realtime_period_ns(ctrl_dt, rate)


@pytest.mark.parametrize('seed', [-1, 2**63, 2**64, 1.5, True, '3'])
def test_seeds_outside_the_sim_range_are_refused_with_the_range(seed):
    with pytest.raises(ScenarioError, match='seed must be'):
        validate_seed(seed)
