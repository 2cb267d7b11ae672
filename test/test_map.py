"""docs/map.md matches the tree, and the layers it promises hold: no rclpy, MuJoCo or torch.

The map's tables list every module of each package folder; the import checks run in a child
whose import system refuses the forbidden libraries, and first prove that it does refuse them.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from helpers import REPO

SRC = REPO / 'src'
PACKAGES = ('nav_sim', 'nav_gym', 'nav_eval')


def map_tables() -> dict[str, set[str]]:
    """Return {dotted folder: the modules its table lists} from docs/map.md."""
    tables: dict[str, set[str]] = {}
    folder = None
    for line in (REPO / 'docs' / 'map.md').read_text().splitlines():
        heading = re.match(r'### (nav_\w+(?:\.\w+)*)', line)
        if heading:
            folder = heading.group(1)
            tables[folder] = set()
        elif folder and (row := re.match(r'\| `(\w+)` \|', line)):
            tables[folder].add(row.group(1))
    return tables


def tree() -> dict[str, set[str]]:
    """Return {dotted folder: its modules} for every package folder under src/."""
    out = {}
    for package in PACKAGES:
        for init in (SRC / package).rglob('__init__.py'):
            folder = init.parent
            out['.'.join(folder.relative_to(SRC).parts)] = {
                p.stem for p in folder.glob('*.py') if p.stem != '__init__'}
    return out


def test_the_map_lists_every_package_folder_and_module_of_the_tree():
    assert map_tables() == tree()


def test_nav_sim_and_nav_gym_have_at_most_eight_modules_at_the_top():
    aliases = {'learner', 'train_config'}  # old paths of pickled classes (docs/map.md)
    for package in ('nav_sim', 'nav_gym'):
        assert len(tree()[package] - aliases) <= 8, tree()[package]


BLOCKER = """
import importlib.abc, sys
BLOCKED = set(sys.argv[1].split(','))
class Refuse(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in BLOCKED:
            raise ImportError(f'{name} is made unimportable')
sys.meta_path.insert(0, Refuse())
for name in sys.argv[2:]:
    __import__(name)
print('imported', len(sys.argv) - 2)
"""


def import_without(blocked: tuple[str, ...], modules: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-c', BLOCKER, ','.join(blocked), *modules],
                          capture_output=True, text=True, timeout=120)


def modules_under(*folders: str) -> list[str]:
    found = []
    for folder in folders:
        path = SRC / Path(*folder.split('.'))
        found += [f'{folder}.{p.stem}' for p in sorted(path.glob('*.py'))
                  if p.stem != '__init__']
    return found


@pytest.mark.parametrize('blocked, modules', [
    (('rclpy',), modules_under('nav_sim.core', 'nav_sim.viz', 'nav_eval.analysis')
     + ['nav_gym.env.reward']),
    (('rclpy', 'mujoco', 'torch'), modules_under('nav_eval.analysis') + ['nav_gym.env.reward']),
    # the policy node on a robot (requirements/robot.txt): an export runs on ONNX Runtime
    (('torch', 'stable_baselines3', 'sb3_contrib', 'mujoco', 'ray'),
     ['nav_gym.policy_node', 'nav_gym.policy.node', 'nav_gym.policy.actors',
      'nav_gym.policy.exported', 'nav_gym.policy.controller']),
])
def test_the_layers_without_ros_import_none_of_the_forbidden_libraries(blocked, modules):
    # the probe can see the thing: a module that needs them fails under the same blocker
    probe = import_without(blocked, ['nav_sim.ros.node' if blocked == ('rclpy',)
                                     else 'nav_sim.core.sim'])
    assert probe.returncode != 0 and 'made unimportable' in probe.stderr
    result = import_without(blocked, modules)
    assert result.returncode == 0, result.stderr
    assert f'imported {len(modules)}' in result.stdout


def test_importing_the_reward_does_not_import_the_env():
    code = ('import sys, nav_gym.env.reward; '
            "print(sorted(m for m in sys.modules if m.startswith('nav_gym.env.')))")
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 0, result.stderr
    assert 'nav_gym.env.navigation' not in result.stdout
    assert 'nav_gym.env.reward' in result.stdout
