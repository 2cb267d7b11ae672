"""The sample-efficiency curve: the scheduled checkpoints, pooled over runs and summaries.

A curve takes the checkpoints of the schedule, not those a stop saved, and pools trials only on
the same held-out scenarios.
"""

from __future__ import annotations

import json

import pytest

from nav_eval.sweeps.statistics import curve_scores
from nav_eval.sweeps.trial import missing_evaluations
from nav_gym.training.config import TrainConfig
from nav_gym.training.run_dir import CONFIG, checkpoint_path, on_schedule


@pytest.mark.parametrize('n_envs, total, saved, curve', [
    (1, 250, [0, 100, 164, 200, 250], [100, 200, 250]),  # 164: a Ctrl-C; 250: the end
    (3, 300, [0, 102, 150, 201, 300], [102, 201, 300]),  # 3 envs pass 100 and 200, meet 300
    (1, 60, [0, 60], [60]),  # a run shorter than the schedule: its end alone
])
def test_the_curve_takes_the_scheduled_checkpoints_and_the_end_not_a_stops(tmp_path, n_envs,
                                                                          total, saved, curve):
    run = tmp_path / 'seed1'
    (run / 'checkpoints').mkdir(parents=True)
    (run / CONFIG).write_text(TrainConfig(checkpoint_freq=100, n_envs=n_envs,
                                          total_timesteps=total).to_yaml())
    for steps in saved:
        checkpoint_path(run, steps).touch()
    trial = {'run_dir': str(run), 'train_seeds': [101], 'heldout_seeds': [201],
             'curve_seeds': [201, 202]}
    todo = missing_evaluations(trial)
    assert todo[0][0] == 'dqn_train,dqn_heldout'  # the final model first
    assert [(names, out.name) for names, _, out in todo[1:]] == [
        ('early_heldout', str(steps)) for steps in curve]


def test_the_schedule_is_the_one_the_saving_callback_keeps():
    # every 100 steps: one env meets each multiple, three envs pass it
    assert [s for s in range(1, 301) if on_schedule(s, 1, 100)] == [100, 200, 300]
    assert [s for s in range(3, 301, 3) if on_schedule(s, 3, 100)] == [102, 201, 300]


def test_a_sweeps_report_leaves_out_a_stops_curve_point_that_an_older_sweep_evaluated(tmp_path):
    from nav_eval.sweeps.collect import read_trial
    run = tmp_path / 'seed1'
    run.mkdir()
    (run / CONFIG).write_text(TrainConfig(checkpoint_freq=100).to_yaml())
    for steps, rate in ((100, 0.5), (164, 0.9), (200, 0.75)):
        out = run / 'eval' / 'curve' / str(steps)
        out.mkdir(parents=True)
        (out / 'results.json').write_text(json.dumps({'sets': [
            {'name': 'early_heldout', 'seeds': [201, 202], 'summary': {'success_rate': rate}}]}))
    curve = read_trial(run)['curve']
    assert {steps: point['success_rate'] for steps, point in curve.items()} == {100: 0.5,
                                                                                 200: 0.75}


def _trial(curve: dict[int, float], exported: bool, seeds=(201, 202)) -> dict:
    return {'curve': {s: {'success_rate': r, 'seeds': list(seeds)} for s, r in curve.items()},
            'exported': exported}


def test_the_curve_pools_runs_with_summaries_that_kept_theirs_on_the_same_scenarios(capsys):
    run = _trial({100: 0.5, 200: 0.9}, exported=False)
    kept = _trial({100: 0.25, 200: 1.0}, exported=True)
    older = _trial({}, exported=True)  # a summary from before summaries kept curves
    curves = curve_scores({'c': [run, kept, older]})
    assert curves['c']['steps'] == [100, 200]
    assert curves['c']['scores'].tolist() == [[[0.5, 0.9]], [[0.25, 1.0]]]
    # on other held-out scenarios the seeds' rates are not one curve's: none, and a line says why
    elsewhere = _trial({100: 1.0, 200: 1.0}, exported=True, seeds=(201, 203))
    assert curve_scores({'c': [run, elsewhere]}) == {}
    assert 'evaluated their checkpoints on different held-out scenarios' in capsys.readouterr().out
