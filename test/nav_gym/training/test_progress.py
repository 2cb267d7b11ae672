"""A training whose output is a log says how far it is (nav_gym.training.progress)."""

from __future__ import annotations

import itertools

from nav_gym.training.progress import duration, progress_callback, progress_line


def test_a_progress_line_gives_the_step_the_rate_the_time_left_and_the_recent_episodes():
    line = progress_line(110_000, 200_000, 19.4, [3.0, 3.42], [True, False, True, True])
    assert line == ('progress: step 110,000 of 200,000 (55 %), 19.4 steps/s, 1 h 17 min to go; '
                    'last 2 episodes: success 75 %, mean return +3.21')


def test_a_progress_line_before_any_episode_or_rate_says_so():
    assert progress_line(0, 50_000, 0.0, [], []) == ('progress: step 0 of 50,000 (0 %); '
                                                    'no episode has ended yet')
    assert progress_line(10, 50, 2.0, [-1.0], []) == ('progress: step 10 of 50 (20 %), 2.0 '
                                                      'steps/s, under a minute to go; '
                                                      'last episode: mean return -1.00')


def test_durations_are_given_to_the_minute():
    assert [duration(s) for s in (0, 29, 31, 3599, 3600, 4620)] == [
        'under a minute', 'under a minute', '1 min', '1 h 0 min', '1 h 0 min', '1 h 17 min']


def test_the_callback_writes_a_line_every_interval_of_training(spaces_only):
    from stable_baselines3 import DQN

    class Episodes(spaces_only):
        """Episodes of 5 steps, each a success."""

        def reset(self, *, seed=None, options=None):
            self.t = 0
            return super().reset(seed=seed)

        def step(self, action):
            self.t += 1
            obs, _, _, _, _ = super().step(action)
            done = self.t % 5 == 0
            return obs, 1.0, done, False, {'is_success': done}

    lines: list[str] = []
    ticks = itertools.count()  # one second a step: the callback reads the clock once per step
    model = DQN('CnnPolicy', Episodes(), buffer_size=100, learning_starts=1000, device='cpu')
    model.learn(40, callback=progress_callback(40, every_s=10, clock=lambda: next(ticks),
                                               write=lines.append))
    assert len(lines) == 4, lines  # at steps 10, 20, 30 and 40
    # SB3 counts an episode after the callback's step: the one ending at step 10 comes next time
    assert lines[0] == ('progress: step 10 of 40 (25 %), 1.0 steps/s, under a minute to go; '
                        'last episode: success 100 %, mean return +5.00')
    assert lines[1].endswith('last 3 episodes: success 100 %, mean return +5.00')
    assert lines[-1].startswith('progress: step 40 of 40 (100 %)')
