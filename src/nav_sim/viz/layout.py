"""The Foxglove layout shipped as ``config/foxglove/visnav.json``, built with ``foxglove.layouts``.

Three tabs.  **Episode**: the camera image as rendered and the 84x84 observation, the top-down 3D
scene (``odom`` frame), the action and episode events, the reward terms, the distance to the goal
and the Q-values.  **Training and time budget**: step, exploration rate, rolling return and
success rate, and the ``/diagnostics`` summary (where a step's time goes).  **Policy node**: the
decisions of ``ros2 run nav_gym policy`` (action, Q-values) and their time budget (the image's
age at each decision, the inference time), live or from a closed-loop evaluation's bag.

Regenerate the file after a change here:
``python -m nav_sim.viz.layout > config/foxglove/visnav.json`` (a test compares them).
"""

from __future__ import annotations

import json
from typing import Any

from nav_sim import interface
from nav_sim.interface import DECISION_FIELDS
from nav_sim.viz.topics import (
    CAMERA_TOPIC,
    DECISION_TOPIC,
    DIAGNOSTICS_TOPIC,
    OBSERVATION_TOPIC,
    ROBOT_TOPIC,
    SCENE_TOPIC,
    STEP_TOPIC,
    TRAINING_TOPIC,
)

#: topics of the layout that exist only live: training statistics and /diagnostics (the time
#: budget).  Every other topic of the layout is also in the evaluation bags.
LIVE_ONLY_TOPICS = (TRAINING_TOPIC, DIAGNOSTICS_TOPIC)
#: the policy node's topics (:data:`nav_sim.viz.topics.POLICY_TOPICS`) are on their own tab: a
#: lockstep evaluation's bag has none, a closed-loop evaluation's bag has them
_TOPIC_KEYS = ('topic', 'imageTopic', 'value', 'topicToRender')


def referenced_topics(layout: Any) -> set[str]:
    """Return every topic a layout's JSON (a dict) references.

    Image and diagnostics topics, message paths (``/topic.field``) and the 3D panel's topics.
    """
    found: set[str] = set()

    def walk(value: Any, key: str = '') -> None:
        if isinstance(value, dict):
            for k, v in value.items():
                if k == 'topics' and isinstance(v, dict):
                    found.update(t for t in v if t.startswith('/'))
                walk(v, k)
        elif isinstance(value, list):
            for item in value:
                walk(item, key)
        elif isinstance(value, str) and value.startswith('/') and key in _TOPIC_KEYS:
            found.add(value.split('.')[0])

    walk(layout)
    return found


def _plot(fl: object, title: str, series: list[tuple[str, str]]) -> object:
    return fl.PlotPanel(title=title, config=fl.PlotConfig(
        paths=[fl.PlotSeries(value=value, label=label) for value, label in series],
        show_legend=True, x_axis_val='timestamp'))


def build_layout() -> object:
    """Build the layout as a ``foxglove.layouts.Layout``."""
    import foxglove.layouts as fl

    def image(title: str, topic: str) -> object:
        return fl.ImagePanel(title=title, config=fl.ImageConfig(
            image_mode=fl.ImageModeConfig(image_topic=topic)))

    def row(*items: tuple[float, object], direction: str = 'row') -> object:
        return fl.SplitContainer(direction=direction, items=[
            fl.SplitItem(proportion=p, content=c) for p, c in items])

    scene = fl.ThreeDeePanel(title='arena (top-down)', config=fl.ThreeDeeConfig(
        follow_tf=interface.ODOM_FRAME, follow_mode='follow-none',
        camera_state=fl.ThreeDeeCameraState(distance=3.2, perspective=False, phi=0.0,
                                            target=(0.0, 0.0, 0.0), theta_offset=0.0),
        topics={SCENE_TOPIC: fl.BaseRendererRosMarkerTopicSettings(visible=True),
                ROBOT_TOPIC: fl.BaseRendererRosMarkerTopicSettings(visible=True)}))
    events = fl.StateTransitionsPanel(title='action and events', config=fl.StateTransitionsConfig(
        paths=[fl.StateTransitionsSeries(value=f'{STEP_TOPIC}.action_name', label='action'),
               fl.StateTransitionsSeries(value=f'{STEP_TOPIC}.event', label='event')]))
    rewards = _plot(fl, 'reward terms', [
        (f'{STEP_TOPIC}.reward', 'reward'), (f'{STEP_TOPIC}.reward_progress', 'progress'),
        (f'{STEP_TOPIC}.reward_step', 'step'), (f'{STEP_TOPIC}.reward_goal', 'goal'),
        (f'{STEP_TOPIC}.reward_collision', 'collision'),
        (f'{STEP_TOPIC}.episode_return', 'return so far')])
    distance = _plot(fl, 'distance to the goal (m)', [(f'{STEP_TOPIC}.distance', 'distance')])
    q_values = _plot(fl, 'Q-values (evaluation)', [
        (f'{STEP_TOPIC}.q_values[{i}]', name) for i, name in enumerate(('left', 'forward',
                                                                         'right'))])
    episode = row(
        (1.0, row((1.0, image('camera (as rendered)', CAMERA_TOPIC)),
                  (1.0, image('observation (84x84)', OBSERVATION_TOPIC)),
                  (1.4, scene), direction='row')),
        (1.0, row((1.0, events), (1.0, rewards), (1.0, distance), (1.0, q_values),
                  direction='row')),
        direction='column')
    training = row(
        (1.0, row((1.0, _plot(fl, 'rolling return', [
                      (f'{TRAINING_TOPIC}.rolling_return', 'return'),
                      (f'{TRAINING_TOPIC}.rolling_length', 'length')])),
                  (1.0, _plot(fl, 'success rate and exploration', [
                      (f'{TRAINING_TOPIC}.rolling_success_rate', 'success rate'),
                      (f'{TRAINING_TOPIC}.exploration_rate', 'epsilon')])),
                  (1.0, _plot(fl, 'steps', [(f'{TRAINING_TOPIC}.num_timesteps', 'step')])),
                  direction='row')),
        (1.0, fl.DiagnosticsSummaryPanel(title='time budget (/diagnostics)',
                                         config=fl.DiagnosticsSummaryConfig(
                                             topic_to_render=DIAGNOSTICS_TOPIC))),
        direction='column')
    return fl.Layout(content=fl.TabContainer(tabs=[
        fl.TabItem(title='Episode', content=episode),
        fl.TabItem(title='Training and time budget', content=training),
        fl.TabItem(title='Policy node', content=_policy_tab(fl, row))]))


def _decision(field: str) -> str:
    """Return the message path of one of the decision's values (its JointState position)."""
    return f'{DECISION_TOPIC}.position[{DECISION_FIELDS.index(field)}]'


def _policy_tab(fl: object, row: object) -> object:
    """Build the policy node's tab: its decisions and their time budget."""
    decisions = _plot(fl, 'policy decisions: action (-1 stop) and Q-values', [
        (_decision('action'), 'action'), (_decision('q_left'), 'Q left'),
        (_decision('q_forward'), 'Q forward'), (_decision('q_right'), 'Q right')])
    command = _plot(fl, 'cmd_vel (m/s, rad/s)', [(_decision('linear'), 'linear'),
                                                  (_decision('angular'), 'angular')])
    budget = _plot(fl, 'decision time budget (ms)', [
        (_decision('image_age_ms'), 'image age (since it arrived)'),
        (_decision('stamp_age_ms'), 'image age (since its stamp, node clock)'),
        (_decision('inference_ms'), 'observation + network')])
    return row((1.0, row((1.0, decisions), (1.0, command), direction='row')),
               (1.0, budget), direction='column')


def layout_json() -> str:
    """Return the layout as indented JSON (what ``config/foxglove/visnav.json`` holds)."""
    return json.dumps(json.loads(build_layout().to_json()), indent=1, sort_keys=True) + '\n'


if __name__ == '__main__':
    print(layout_json(), end='')
