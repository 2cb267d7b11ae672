"""The install layout that ``ros2 run`` and ``get_package_share_directory`` rely on."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest
from ament_index_python.packages import get_package_prefix, get_package_share_directory

from nav_sim.errors import WorldNotFoundError
from nav_sim.paths import executable_path, find_world


@pytest.mark.parametrize('package', ['nav_sim', 'nav_gym', 'nav_eval'])
def test_packages_are_registered_in_the_ament_index(package):
    prefix = Path(get_package_prefix(package))
    assert prefix.resolve() == Path(sys.prefix).resolve()
    assert (Path(get_package_share_directory(package)) / 'package.xml').is_file()


def test_ros2_run_resolves_the_sim_node_executable():
    # ros2run: <get_package_prefix(pkg)>/lib/<pkg>/<executable>, which must be executable;
    # executable_path (what node_command starts) finds the same file
    path = Path(get_package_prefix('nav_sim')) / 'lib' / 'nav_sim' / 'sim_node'
    assert path.is_file() and os.access(path, os.X_OK)
    assert executable_path('nav_sim', 'sim_node') == path


def test_worlds_and_params_are_installed_in_share():
    share = Path(get_package_share_directory('nav_sim'))
    assert (share / 'worlds' / 'arena.xml').is_file()
    assert (share / 'config' / 'sim.yaml').is_file()
    assert find_world('arena.xml') == share / 'worlds' / 'arena.xml'


def test_missing_world_names_the_paths_searched():
    with pytest.raises(WorldNotFoundError) as info:
        find_world('no_such_world.xml')
    assert 'share/nav_sim/worlds/no_such_world.xml' in str(info.value)


def test_console_script_is_installed():
    script = Path(sys.prefix) / 'bin' / 'nav-sim'
    assert script.is_file()
    out = subprocess.run([str(script), '--ros-args', '-p', 'mode:=bogus'], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 2
    assert 'mode must be one of' in out.stdout + out.stderr
    assert 'Traceback' not in out.stderr


def test_params_file_lists_every_parameter_with_its_default():
    import dataclasses

    import yaml

    from nav_sim.core.config import SimConfig
    from nav_sim.ros.settings import NodeConfig
    share = Path(get_package_share_directory('nav_sim'))
    params = yaml.safe_load((share / 'config' / 'sim.yaml').read_text())['/**']['ros__parameters']
    fields = dataclasses.fields(SimConfig) + dataclasses.fields(NodeConfig)
    assert params == {f.name: f.default for f in fields}
