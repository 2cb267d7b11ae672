"""The sample-efficiency curve: the scheduled checkpoints, pooled over runs and summaries.

A curve takes the checkpoints of the schedule, not those a stop saved, and pools trials only on
the same held-out scenarios.
"""

from __future__ import annotations

import json

import pytest

from nav_eval.sweeps.collect import read_exported
from nav_eval.sweeps.statistics import curve_scores, per_seed_rows
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


def _trial(curve: dict[int, float], exported: bool, seeds=(201, 202), name='t') -> dict:
    return {'curve': {s: {'success_rate': r, 'seeds': list(seeds)} for s, r in curve.items()},
            'exported': exported, 'name': name}


def test_the_curve_pools_runs_with_summaries_that_kept_theirs_on_the_same_scenarios(capsys):
    run = _trial({100: 0.5, 200: 0.9}, exported=False)
    kept = _trial({100: 0.25, 200: 1.0}, exported=True)
    older = _trial({}, exported=True, name='old:seed1')  # a summary that kept no curve
    curves = curve_scores({'c': [run, kept, older]})
    assert curves['c']['steps'] == [100, 200]
    assert curves['c']['scores'].tolist() == [[[0.5, 0.9]], [[0.25, 1.0]]]
    assert 'leaves out old:seed1' in capsys.readouterr().out
    # the same scenarios in another order are the same scenarios
    assert curve_scores({'c': [run, _trial({100: 1.0, 200: 1.0}, True, seeds=(202, 201))]})
    # on other held-out scenarios the seeds' rates are not one curve's: none, and a line says why
    elsewhere = _trial({100: 1.0, 200: 1.0}, exported=True, seeds=(201, 203))
    assert curve_scores({'c': [run, elsewhere]}) == {}
    assert 'evaluated their checkpoints on different held-out scenarios' in capsys.readouterr().out


def _summary(folder, trials: list[dict]) -> None:
    """Write ``trials`` as a summary's results.json writes them (keys sorted as text)."""
    folder.mkdir()
    (folder / 'results.json').write_text(json.dumps(
        {'per_seed': per_seed_rows({'c': trials}), 'settings': {}}, sort_keys=True))


def test_a_summary_keeps_each_trials_curve_through_json_and_a_later_copy_fills_a_first_without(
        tmp_path, capsys):
    final = {'heldout': {'summary': {'success_rate': 1.0, 'collision_rate': 0.0,
                                     'timeout_rate': 0.0, 'mean_spl': 0.5, 'episodes': 2}}}

    def trial(name, curve, **more):
        return {'seed': 1, 'steps': 100_000, 'wall_clock_s': 1.0, 'final': final,
                **_trial(curve, exported=False, name=name), **more}

    # 50000 sorts after 100000 as text: the curve must come back by number
    kept = trial('seed1', {50_000: 0.5, 100_000: 0.75})
    _summary(tmp_path / 'a', [trial('seed1', {})])  # an older copy of the same trial: no curve
    _summary(tmp_path / 'b', [kept])
    _summary(tmp_path / 'c', [trial('seed2', {50_000: 1.0, 100_000: 1.0}, wall_clock_s=2.0)])
    # a trial whose checkpoints were evaluated on different scenarios keeps no curve
    mixed = trial('seed3', {50_000: 1.0}, wall_clock_s=3.0)
    mixed['curve'][100_000] = {'success_rate': 1.0, 'seeds': [203]}
    assert 'curve' not in per_seed_rows({'c': [mixed]})[0]
    trials = read_exported([tmp_path / 'a', tmp_path / 'b', tmp_path / 'c'])
    assert [t['name'] for t in trials] == ['a:seed1', 'c:seed2']  # b's seed1 is a's, once
    assert trials[0]['curve'] == kept['curve']
    assert curve_scores({'c': trials})['c']['steps'] == [50_000, 100_000]
    # a summary's trial without a curve still counts elsewhere; the curve says it leaves it out
    _summary(tmp_path / 'd', [trial('seed4', {}, wall_clock_s=4.0)])
    trials += read_exported([tmp_path / 'd'])
    assert curve_scores({'c': trials})['c']['scores'].shape == (2, 1, 2)
    assert 'the sample-efficiency curve leaves out d:seed4' in capsys.readouterr().out
