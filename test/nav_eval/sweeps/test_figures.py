"""The sweep report's figures keep their plot in place whatever a configuration is named."""

from __future__ import annotations

import numpy as np
from PIL import Image

from nav_eval.sweeps.figures import LEGEND_WIDTH, _profile, _wrapped

LONG = ('world=rooms.xml_frame_stack=4_previous_action=true_gradient_steps=2_reset_interval=20000_'
        'checkpoint_freq=50000_total_tim')


def test_a_long_configuration_name_wraps_between_settings_and_leaves_the_figure_its_size(
        tmp_path):
    assert _wrapped(LONG).split('\n') == [
        'world=rooms.xml_frame_stack=4_', 'previous_action=true_gradient_steps=2_',
        'reset_interval=20000_checkpoint_freq=50000_', 'total_tim']
    # a folder of runs joins settings with ', '; short names stay as they are
    runs = 'max_episode_steps=200, min_start_goal_distance=1.0, num_obstacles=4, world=rooms.xml'
    assert _wrapped(runs).split('\n') == [
        'max_episode_steps=200,', 'min_start_goal_distance=1.0, num_obstacles=4,',
        'world=rooms.xml']
    assert _wrapped('defaults') == 'defaults'
    assert all(len(line) <= LEGEND_WIDTH + 1 for line in _wrapped(LONG).split('\n'))
    sizes = []
    for name in ('defaults', LONG):
        folder = tmp_path / name[:8]
        _profile(folder, {name: np.array([[0.90], [0.95], [0.97]])})
        with Image.open(folder / 'performance_profile.png') as image:
            sizes.append(image.size)
    assert sizes[0] == sizes[1], sizes  # unwrapped, the long name made it 956 px wide, not 575
