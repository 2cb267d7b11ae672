"""The sweep on local Ray Tune, end to end: trials, evaluation, aggregation, resume, faults.

Each sweep starts its own Ray (seconds) and trains tiny trials (200 steps, 2 + 2 evaluation
scenarios), so one sweep is shared by the assertions that only read it.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from helpers import wait_until
from nav_eval.sweeps.report import SECTIONS
from nav_eval.sweeps.trial import train_args
from nav_gym.training.spec import LEGACY_DEFAULTS

TINY = ['--total-timesteps', '200', '--set', 'learning_starts=100', '--set', 'checkpoint_freq=100',
        '--set', 'buffer_size=500', '--set', 'max_episode_steps=12', '--train-seeds', '101-102',
        '--heldout-seeds', '201-202', '--curve-seeds', '201', '--cpus-per-trial', '1']
REPORT_FILES = ('Sweep.md', 'Sweep.html', 'results.json')
# one configuration, named by its --set settings (trials keep the plain names seed1, seed2)
CONFIG = ('learning_starts=100_checkpoint_freq=100_buffer_size=500_max_episode_steps=12_'
          'total_timesteps=200')


def sweep(*args: str, timeout: float = 900) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'nav_eval.sweep', *args], capture_output=True,
                          text=True, timeout=timeout)


def explain(result: subprocess.CompletedProcess) -> str:
    return result.stdout[-4000:] + result.stderr[-4000:]


@pytest.fixture(scope='module')
def finished(tmp_path_factory) -> tuple[Path, subprocess.CompletedProcess]:
    storage = tmp_path_factory.mktemp('sweeps')
    result = sweep('--seeds', '1-2', *TINY, '--storage', str(storage), '--name', 's',
                   '--summary', str(storage / 'kept'))
    return storage / 's', result


def snapshot(folder: Path) -> dict[str, bytes]:
    files = [folder / n for n in REPORT_FILES] + sorted((folder / 'figures').glob('*.png'))
    return {p.name: p.read_bytes() for p in files}


def test_a_two_seed_sweep_trains_evaluates_and_aggregates(finished):
    folder, result = finished
    assert result.returncode == 0, explain(result)
    for seed in (1, 2):
        run = folder / 'trials' / f'seed{seed}'
        assert (run / 'final_model.zip').is_file()
        assert yaml.safe_load((run / 'config.yaml').read_text())['seed'] == seed
        assert not (run / 'checkpoints' / 'replay_buffer.pkl').exists()  # a finished trial
        sets = json.loads((run / 'eval' / 'results.json').read_text())['sets']
        assert {s['name']: s['seeds'] for s in sets} == {'dqn_train': [101, 102],
                                                       'dqn_heldout': [201, 202]}
        assert sorted(int(p.name) for p in (run / 'eval' / 'curve').iterdir()) == [100, 200]
        assert re.search(rf'\] done  seed{seed} in \d+ s: held-out success \d+%', result.stdout)
    baselines = json.loads((folder / 'baselines' / f'{CONFIG}.json').read_text())
    assert [s['name'] for s in baselines['sets']] == ['random_train', 'random_heldout',
                                                      'servo_train', 'servo_heldout',
                                                      'oracle_train', 'oracle_heldout']
    assert 'ETA' in result.stdout and 'start seed1' in result.stdout
    report = (folder / 'Sweep.md').read_text()
    for heading in SECTIONS:
        if heading != 'Probability of improvement':  # only with more than one configuration
            assert f'## {heading}' in report, heading
    assert '## Missing' not in report and '## Failed' not in report
    html = (folder / 'Sweep.html').read_text()
    assert 'src="figures/' not in html and html.count('data:image/png;base64,') == 4
    results = json.loads((folder / 'results.json').read_text())
    assert results['configurations'] == {CONFIG: ['seed1', 'seed2']}
    iqm = results['aggregates']['success_rate'][CONFIG]['IQM']
    assert {(r['seed'], r['config']) for r in results['anatomy']} >= {(1, CONFIG), (2, CONFIG),
                                                                      ('all', CONFIG)}
    assert iqm['low'] <= iqm['point'] <= iqm['high']
    assert {r['policy'] for r in results['banks']} == {'random', 'servo', 'oracle',
                                                       'DQN final (all seeds pooled)'}
    gap = results['oracle_gap'][CONFIG]
    assert gap['gap'] == gap['oracle'] - iqm['point']  # 12 decisions: too few for the oracle
    assert f'Gap to the oracle, `{CONFIG}`' in (folder / 'Sweep.md').read_text()


def test_trials_ran_at_once_in_different_domains(finished):
    folder, result = finished
    assert result.returncode == 0, explain(result)
    assert re.search(r'start seed\d \(1 running', result.stdout)  # the second joined the first
    domains = {}
    for seed in (1, 2):
        log = (folder / 'logs' / f'seed{seed}.log').read_text()
        domains[seed] = set(re.findall(r'ROS_DOMAIN_ID=(\d+)', log))
    assert domains[1] and domains[2] and not domains[1] & domains[2]


def test_aggregating_again_gives_identical_files_and_resume_runs_nothing(finished):
    folder, result = finished
    assert result.returncode == 0, explain(result)
    before = snapshot(folder)
    logs = {p.name: p.read_text() for p in (folder / 'logs').iterdir()}
    again = sweep('--aggregate', str(folder), timeout=300)
    assert again.returncode == 0, explain(again)
    assert snapshot(folder) == before
    settings = (folder / 'sweep.json').read_bytes()
    # its own summary again, with this session's CPUs (not kept in sweep.json)
    resumed = sweep('--resume', str(folder), '--summary', str(folder.parent / 'kept'),
                    '--cpus-per-trial', '2', timeout=600)
    assert resumed.returncode == 0, explain(resumed)
    assert 'start ' not in resumed.stdout and '2 CPU per trial' in resumed.stdout
    assert (folder / 'sweep.json').read_bytes() == settings
    assert {p.name: p.read_text() for p in (folder / 'logs').iterdir()} == logs
    assert snapshot(folder) == before


def test_the_kept_summary_is_the_sweeps_export_rewritten_after_each_trial(finished, tmp_path):
    folder, result = finished
    assert result.returncode == 0, explain(result)
    kept = folder.parent / 'kept'
    # after seed1, seed2 and the baselines, and once more at the end
    assert result.stdout.count(f'sweep summary: {kept}') == 4, explain(result)
    exported = sweep('--export', str(folder), str(tmp_path / 'exp'), timeout=300)
    assert exported.returncode == 0, explain(exported)
    files = sorted(str(p.relative_to(kept)) for p in kept.rglob('*'))
    assert files == sorted(str(p.relative_to(tmp_path / 'exp'))
                           for p in (tmp_path / 'exp').rglob('*'))
    for name in ('Sweep.md', 'results.json', 'sweep.json'):
        assert (kept / name).read_bytes() == (tmp_path / 'exp' / name).read_bytes(), name
    assert sorted(p.name for p in folder.parent.iterdir()) == ['kept', 's']  # no leftovers
    assert json.loads((folder / 'sweep.json').read_text())['summary'] == str(kept)


def test_a_kept_summary_replaces_only_its_own_sweeps(tmp_path, capsys):
    from nav_eval.errors import SweepError
    from nav_eval.sweeps.spec import SWEEP_FILE, SweepSpec, summary_folder, summary_swap
    from nav_eval.sweeps.tune import AfterEachTrial
    mine = SweepSpec(str(tmp_path / 'runs' / 'sweep'), [1, 2], sweep_id='a1')
    assert summary_folder(None, mine) == ''
    assert summary_folder(tmp_path / 'new', mine) == str(tmp_path / 'new')
    (tmp_path / 'empty').mkdir()
    assert summary_folder(tmp_path / 'empty', mine) == str(tmp_path / 'empty')
    # its own summary, whatever summary folder its sweep.json named then; another sweep's,
    # though its settings are the same, or one from before sweeps had an id, is not
    for name, kept in (('own', {'sweep_id': 'a1'}), ('twin', {'sweep_id': 'b2'}),
                       ('older', {}), ('docs', None)):
        (tmp_path / name).mkdir()
        text = 'not a summary' if kept is None else json.dumps(
            {'seeds': [1, 2], 'summary': str(tmp_path / 'elsewhere'), **kept})
        (tmp_path / name / SWEEP_FILE).write_text(text)
    assert summary_folder(tmp_path / 'own', mine) == str(tmp_path / 'own')
    for taken in ('twin', 'older', 'docs', f'own/{SWEEP_FILE}'):
        with pytest.raises(SweepError, match="exists and is not this sweep's summary"):
            summary_folder(tmp_path / taken, mine)
    with pytest.raises(SweepError, match="exists and is not this sweep's summary"):
        summary_folder(tmp_path / 'own', SweepSpec(mine.sweep_dir, [1, 2]))  # a sweep from before
    # the sweep's directory, a folder in it, or one that holds it: the swap would lose the sweep
    for overlap in ('runs/sweep', 'runs/sweep/summary', 'runs', '.'):
        with pytest.raises(SweepError, match='overlaps the sweep directory'):
            summary_folder(tmp_path / overlap, mine)
    # a stop between the swap's two renames: the summary it was replacing is put back
    fresh, old = summary_swap(tmp_path / 'own')
    assert (fresh.name, old.name) == ('.own.new', '.own.old')
    (tmp_path / 'own').rename(old)
    fresh.mkdir()
    assert summary_folder(tmp_path / 'own', mine) == str(tmp_path / 'own')
    assert json.loads((tmp_path / 'own' / SWEEP_FILE).read_text())['sweep_id'] == 'a1'
    assert not old.exists()
    # a failed copy is one line, and the sweep goes on
    from types import SimpleNamespace
    AfterEachTrial(lambda: 1 / 0).on_trial_complete(
        0, [], SimpleNamespace(config={'trial': {'name': 'seed1'}}))
    assert capsys.readouterr().out == 'after seed1: ZeroDivisionError: division by zero\n'


def copy_run(source: Path, copy: Path, turn_speed: float | None, *leave_out: str) -> None:
    """Copy a run without its checkpoints and TensorBoard logs, with another turn_speed."""
    shutil.copytree(source, copy, ignore=shutil.ignore_patterns('checkpoints', 'tb', *leave_out))
    if turn_speed is not None:
        config = yaml.safe_load((copy / 'config.yaml').read_text())
        config['turn_speed'] = turn_speed
        (copy / 'config.yaml').write_text(yaml.safe_dump(config))


def test_aggregate_a_folder_of_runs_with_two_configurations(finished, tmp_path):
    folder, result = finished
    assert result.returncode == 0, explain(result)
    for seed in (1, 2):
        for label, turn_speed in (('a', None), ('b', 0.02)):
            copy_run(folder / 'trials' / f'seed{seed}', tmp_path / f'{label}{seed}', turn_speed,
                     'traces')
    done = sweep('--aggregate', str(tmp_path), timeout=300)
    assert done.returncode == 0, explain(done)
    results = json.loads((tmp_path / 'results.json').read_text())
    assert results['configurations'] == {'turn_speed=0.03': ['a1', 'a2'],
                                         'turn_speed=0.02': ['b1', 'b2']}
    report = (tmp_path / 'Sweep.md').read_text()
    assert '## Probability of improvement' in report
    assert set(results['improvement']) == {'turn_speed=0.03 > turn_speed=0.02',
                                           'turn_speed=0.02 > turn_speed=0.03'}
    # and the same pairs on collisions: P(X has fewer), as 1 - collision rate
    assert set(results['improvement_collisions']) == set(results['improvement'])
    assert 'episodes without a collision (1 - collision rate)' in report


def test_a_run_from_before_a_sim_setting_groups_with_its_new_twin(finished, tmp_path):
    """A run saved before ``obstacle_gap`` and ``randomize_look`` existed ran at their defaults."""
    folder, result = finished
    assert result.returncode == 0, explain(result)
    for seed in (1, 2):
        shutil.copytree(folder / 'trials' / f'seed{seed}', tmp_path / f'seed{seed}',
                        ignore=shutil.ignore_patterns('checkpoints', 'tb', 'traces'))
    older = tmp_path / 'seed2' / 'config.yaml'
    config = yaml.safe_load(older.read_text())
    for name in ('obstacle_gap', 'randomize_look'):
        del config['sim_params'][name]
    older.write_text(yaml.safe_dump(config))
    done = sweep('--aggregate', str(tmp_path), timeout=300)
    assert done.returncode == 0, explain(done)
    configurations = json.loads((tmp_path / 'results.json').read_text())['configurations']
    assert list(configurations.values()) == [['seed1', 'seed2']], configurations
    assert 'None' not in (tmp_path / 'Sweep.md').read_text()


def test_exported_summaries_aggregate_with_runs_by_their_settings(finished, tmp_path):
    """A summary (--export) keeps per-seed rates: its trials join runs of the same settings."""
    folder, result = finished
    assert result.returncode == 0, explain(result)
    exported = sweep('--export', str(folder), str(tmp_path / 'exp'), timeout=300)
    assert exported.returncode == 0, explain(exported)
    # an older summary: made before aux_depth and randomize_look existed (their defaults)
    older = tmp_path / 'exp' / 'results.json'
    data = json.loads(older.read_text())
    for settings in data['settings'].values():
        del settings['aux_depth'], settings['sim_params']['randomize_look']
        settings['checkpoint_freq'] = 7  # bookkeeping: no other configuration
    older.write_text(json.dumps(data))
    # the same summary once more, as a comparison's export that holds its trials: counted once
    shutil.copytree(tmp_path / 'exp', tmp_path / 'zcmp')
    again = tmp_path / 'zcmp' / 'results.json'
    data = json.loads(again.read_text())
    for row in data['per_seed']:
        row['trial'] = f"exp:{row['trial']}"
    again.write_text(json.dumps(data))
    # one from before n_steps and double_q: 1-step DQN then (LEGACY_DEFAULTS), not today's
    shutil.copytree(tmp_path / 'exp', tmp_path / 'old')
    oldest = tmp_path / 'old' / 'results.json'
    data = json.loads(oldest.read_text())
    for settings in data['settings'].values():
        del settings['n_steps'], settings['double_q']
    data['per_seed'] = data['per_seed'][:1]
    data['per_seed'][0]['wall_clock_s'] = 1.0  # another run than exp's
    oldest.write_text(json.dumps(data))
    for name, turn_speed in (('a1', None), ('b1', 0.02), ('b2', 0.02)):
        copy_run(folder / 'trials' / f'seed{name[1]}', tmp_path / name, turn_speed)
    done = sweep('--aggregate', str(tmp_path), timeout=300)
    assert done.returncode == 0, explain(done)
    results = json.loads((tmp_path / 'results.json').read_text())
    # labels name what differs between the three: turn_speed, and double_q and n_steps
    today, turn, legacy = ('double_q=True, n_steps=3, turn_speed=0.03',
                           'double_q=True, n_steps=3, turn_speed=0.02',
                           'double_q=False, n_steps=1, turn_speed=0.03')
    assert results['configurations'] == {today: ['a1', 'exp:seed1', 'exp:seed2'],
                                         turn: ['b1', 'b2'], legacy: ['old:seed1']}
    original = {r['trial']: r for r in json.loads(
        (folder / 'results.json').read_text())['per_seed']}
    rows = {r['trial']: r for r in results['per_seed']}
    for seed in (1, 2):
        mine, theirs = rows[f'exp:seed{seed}'], original[f'seed{seed}']
        for key in ('seed', 'steps', 'heldout_success_rate', 'heldout_collision_rate',
                    'train_success_rate', 'heldout_episodes'):
            assert mine[key] == theirs[key], key
    assert results['aggregates']['success_rate'][today]['IQM']
    assert f'{today} > {turn}' in results['improvement']
    # the runs' curve stays, and a summary's trials bring their own: old:seed1 is a summary's alone
    assert results['sample_efficiency'][today]['steps']
    curve = {r['trial']: r['curve'] for r in results['per_seed'] if 'curve' in r}
    assert curve['old:seed1'] == curve['a1'] == original['seed1']['curve'], curve
    assert results['sample_efficiency'][legacy]['steps'] == sorted(
        int(s) for s in original['seed1']['curve'])
    # a summary keeps no episodes: the pooled bank row would hold one seed of three
    pooled = {r['config'] for r in results['banks'] if r['policy'].startswith('DQN')}
    assert pooled == {turn}
    # the runs' own anatomy stays; the summary's trials add none
    assert {r['config'] for r in results['anatomy']} == {today, turn}


def test_aggregating_a_folder_without_runs_or_summaries_says_what_it_needs(tmp_path):
    (tmp_path / 'notes').mkdir()
    done = sweep('--aggregate', str(tmp_path), timeout=120)
    assert done.returncode != 0
    assert 'holds no run directories (trials/*/config.yaml) and no sweep summaries' in \
        done.stderr, explain(done)


def test_the_report_names_the_command_that_completes_each_missing_trial(finished, tmp_path):
    folder, result = finished
    assert result.returncode == 0, explain(result)
    copy = tmp_path / 's'
    shutil.copytree(folder, copy, ignore=shutil.ignore_patterns('tune', 'checkpoints', 'tb'))
    runs = tmp_path / 'runs'
    for seed in (1, 2):
        shutil.copytree(copy / 'trials' / f'seed{seed}', runs / f'seed{seed}')
    # seed1: training interrupted (no final model, no evaluation); seed2: not evaluated
    for base in (copy / 'trials', runs):
        (base / 'seed1' / 'final_model.zip').unlink()
        shutil.rmtree(base / 'seed1' / 'eval')
        (base / 'seed2' / 'eval' / 'results.json').unlink()
    for target in (copy, runs):
        done = sweep('--aggregate', str(target), timeout=300)
        assert done.returncode == 0, explain(done)
    missing = json.loads((copy / 'results.json').read_text())['missing']
    assert missing == [f'seed1: training unfinished; run `visnav-sweep --resume {copy}`',
                       f'seed2: no final evaluation; run `visnav-sweep --resume {copy}`']
    first, second = json.loads((runs / 'results.json').read_text())['missing']
    assert first == (f'seed1: training unfinished; run `nav-gym-train --resume {runs}/seed1`, '
                     'then evaluate it')
    assert second.startswith(f'seed2: no final evaluation; run `nav-eval-evaluate {runs}/seed2 ')
    assert '## Missing' in (runs / 'Sweep.md').read_text()


def test_bad_settings_are_one_line_errors(tmp_path):
    (tmp_path / 'docs').mkdir()
    (tmp_path / 'docs' / 'README.md').write_text('not a summary')
    for args, words in ((['--grid', 'nonsense=1,2'], 'unknown setting'),
                        (['--grid', 'turn_speed='], 'bad setting'),
                        (['--set', 'learning_rate=fast'], 'learning_rate'),
                        (['--set', f'world={tmp_path}/no_such.xml'], 'no_such.xml not found'),
                        (['--grid', 'world=arena.xml,no_such'], "world 'no_such' not found"),
                        (['--set', 'num_obstacles=9'], 'but num_obstacles is 9'),
                        (['--summary', str(tmp_path / 'docs')], "is not this sweep's summary"),
                        (['--summary', str(tmp_path / 'runs')], 'overlaps the sweep directory')):
        result = sweep(*args, '--storage', str(tmp_path / 'runs'), '--name', 'bad',
                       timeout=120)
        assert result.returncode == 1 and words in result.stderr, explain(result)
        assert 'Traceback' not in result.stderr and len(result.stderr.splitlines()) == 1
        assert not (tmp_path / 'runs' / 'bad').exists()  # refused before anything is written


def test_a_failing_trial_is_retried_then_reported(tmp_path):
    # the world loads (its settings are checked before Ray), but no layout fits 0.6 m gaps
    result = sweep('--seeds', '1', *TINY, '--set', 'obstacle_gap=0.6', '--no-baselines',
                   '--storage', str(tmp_path), '--name', 'f', timeout=600)
    assert result.returncode == 1, explain(result)
    assert 'retry seed1' in result.stdout and 'FAILED seed1' in result.stdout
    assert 'trial seed1 FAILED (tried 2 times)' in result.stdout
    assert 'world arena.xml: could not place' in result.stdout  # the cause, from the trial's log
    report = (tmp_path / 'f' / 'Sweep.md').read_text()
    assert '## Failed trials' in report and 'num_obstacles' in report


def descendants(pid: int) -> list[int]:
    """Every process below ``pid`` (from /proc)."""
    parents: dict[int, list[int]] = {}
    for stat in Path('/proc').glob('[0-9]*/stat'):
        try:
            fields = stat.read_text().rsplit(')', 1)[1].split()
        except OSError:
            continue
        parents.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    out, front = [], [pid]
    while front:
        front = [c for p in front for c in parents.get(p, [])]
        out += front
    return out


def running(pid: int) -> bool:
    try:
        state = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0]
    except OSError:
        return False
    return state != 'Z'


def command_line(pid: int) -> str:
    try:
        return Path(f'/proc/{pid}/cmdline').read_bytes().replace(b'\0', b' ').decode()
    except OSError:
        return ''


def test_ctrl_c_leaves_no_process_and_a_resumable_sweep(tmp_path):
    # exactly two trials fit at once, whatever the CPU count
    args = [*TINY, '--total-timesteps', '50000', '--curve-seeds', '',
            '--cpus-per-trial', str(max(1.0, (os.cpu_count() or 2) / 2))]
    # seeds 1 and 2 run at once (1 CPU each on 2), seed 3 waits: Ctrl-C stops it unstarted
    process = subprocess.Popen([sys.executable, '-m', 'nav_eval.sweep', '--seeds', '1-3', *args,
                                '--no-baselines', '--storage', str(tmp_path), '--name', 'c'],
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    folder = tmp_path / 'c'
    try:
        started = [folder / 'trials' / f'seed{s}' / 'checkpoints' / 'dqn_0_steps.zip'
                   for s in (1, 2)]

        def training() -> bool:  # both trainers are training
            if all(p.is_file() for p in started):
                return True
            assert process.poll() is None
            return False

        wait_until(training, 300, 'the first checkpoint of seeds 1 and 2', interval=0.5)
        below = descendants(process.pid)
        lines = [command_line(p) for p in below]
        assert sum('nav_sim.sim_node' in c or 'sim_node' in c for c in lines) >= 2, lines
        assert any('raylet' in c for c in lines)
        assert sum('-m nav_eval.sweep_trial' in c for c in lines) == 2  # the trials' trainers
        process.send_signal(signal.SIGINT)
        output, _ = process.communicate(timeout=180)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 130, output[-3000:]
    assert f'visnav-sweep --resume {folder}' in output
    try:  # the trainers save a checkpoint, then exit
        wait_until(lambda: not any(running(p) for p in below), 90,
                   "the sweep's processes ending", interval=0.5,
                   details=lambda: [f'{p}: {command_line(p)}' for p in below if running(p)])
    finally:
        for pid in below:  # clean up before failing, so a failure leaves nothing behind
            if running(pid):
                os.kill(pid, signal.SIGKILL)
    # resumed, the sweep schedules its started trials first, whatever order Tune restores
    from nav_eval.sweeps.spec import load_spec
    from nav_eval.sweeps.tune import StartedFirst, _tuner
    resumed = load_spec(folder)
    tuner, _ = _tuner(resumed, resumed.trials(), True, False, set(), after_each=print)
    assert isinstance(tuner._local_tuner._tune_config.scheduler, StartedFirst)
    # and fresh callbacks, the summary keeper's among them
    assert [type(c).__name__ for c in tuner._local_tuner._run_config.callbacks] == [
        'ProgressLines', 'AfterEachTrial']
    spec = json.loads((folder / 'sweep.json').read_text())
    for seed in (1, 2):
        trial = {'run_dir': str(folder / 'trials' / f'seed{seed}'), 'gpus': 0,
                 'config_file': '', 'seed': seed}
        assert '--resume' in train_args(trial)  # continues from its newest checkpoint
    assert spec['seeds'] == [1, 2, 3]
    assert not (folder / 'trials' / 'seed3').exists()


def test_a_resumed_sweep_runs_the_trials_it_started_first(tmp_path):
    from types import SimpleNamespace

    from nav_eval.sweeps.tune import StartedFirst
    trials = [{'name': f'seed{i}', 'log': str(tmp_path / f'seed{i}.log')} for i in (1, 2, 3, 4)]
    order = [t['name'] for t in trials]
    # Tune restores them in no set order; seed3 ran in an earlier session, seed4 is running
    fake = [SimpleNamespace(config={'trial': trials[i]}, status=status)
            for i, status in ((1, 'PENDING'), (3, 'RUNNING'), (2, 'PENDING'), (0, 'PENDING'))]
    controller = SimpleNamespace(get_trials=lambda: fake)
    scheduler = StartedFirst(order)
    assert scheduler.choose_trial_to_run(controller).config['trial']['name'] == 'seed1'
    Path(trials[2]['log']).write_text('# attempt at ...\n')  # seed3 had started
    assert scheduler.choose_trial_to_run(controller).config['trial']['name'] == 'seed3'
    for trial in fake:
        trial.status = 'TERMINATED' if trial.status == 'PENDING' else trial.status
    assert scheduler.choose_trial_to_run(controller) is None
    fake[0].status = 'PAUSED'
    assert scheduler.choose_trial_to_run(controller) is fake[0]


def test_eta_times_each_kind_of_trial_on_its_own():
    from nav_eval.sweeps.tune import eta_text
    durations = {'train': [600.0, 700.0], 'baseline': [60.0]}
    # 3 training trials of ~650 s and one baseline of ~60 s, not 4 x the mean of all three
    assert eta_text(durations, {'train': 3, 'baseline': 1}, 1) == '00:33:30'
    # two at once: 2 waves of training trials, 1 of baselines
    assert eta_text(durations, {'train': 3, 'baseline': 1}, 2) == '00:22:40'
    # a kind with no finished trial yet takes the mean of all finished trials
    assert eta_text({'baseline': [60.0]}, {'train': 1, 'baseline': 0}, 1) == '00:01:00'
    assert eta_text(durations, {'train': 0, 'baseline': 0}, 1) == '0 s'
    assert eta_text({}, {'train': 2}, 1) == '–'


def test_progress_counts_each_trial_once_across_a_resume(capsys):
    from types import SimpleNamespace

    from nav_eval.sweeps.tune import ProgressLines
    trials = [{'name': f'seed{i}', 'kind': 'train', 'log': 'x.log'} for i in (1, 2, 3)]
    trials.append({'name': 'baselines', 'kind': 'baseline', 'log': 'y.log'})
    fake = {t['name']: SimpleNamespace(config={'trial': t}, status='RUNNING') for t in trials}
    progress = ProgressLines(trials, done={'seed1', 'not-a-trial'})  # seed1 ended before
    assert (progress.ended, progress.total, dict(progress.remaining)) == (1, 4, {'train': 2,
                                                                                 'baseline': 1})
    for name in ('seed1', 'seed2', 'seed2'):  # seed1 re-runs nothing; seed2 reported twice
        progress.on_trial_start(0, list(fake.values()), fake[name])
        progress.on_trial_complete(0, list(fake.values()), fake[name])
    assert progress.ended == 2 and dict(progress.remaining) == {'train': 1, 'baseline': 1}
    assert list(progress.durations) == ['train'] and len(progress.durations['train']) == 1
    progress.on_trial_error(0, list(fake.values()), fake['seed3'])
    assert progress.ended == 3 and progress.remaining['train'] == 0
    assert 'FAILED seed3 (3 of 4 done)' in capsys.readouterr().out


def test_configuration_and_trial_names_and_those_of_older_sweeps(tmp_path):
    from nav_eval.sweeps.spec import NAMING, SweepSpec

    def names(**kw):
        return [(t['name'], t['config']) for t in SweepSpec(str(tmp_path), [1], **kw).trials()
                if t['kind'] == 'train']

    fixed = {'turn_rate': '0.5'}
    assert names(naming=NAMING) == [('seed1', 'defaults')]
    assert names(fixed=fixed, naming=NAMING) == [('seed1', 'turn_rate=0.5')]
    assert names(grid={'a': ['1', '2']}, fixed=fixed, naming=NAMING) == [('a=1_seed1', 'a=1'),
                                                                         ('a=2_seed1', 'a=2')]
    assert names(grid={'a': ['1']}, naming=NAMING) == [('seed1', 'a=1')]
    # a sweep.json written before configurations were named by --set (no 'naming'): as then
    assert names(fixed=fixed) == [('seed1', 'defaults')]
    assert names(grid={'a': ['1']}) == [('a=1_seed1', 'a=1')]
    # every trial is a run of that name: a grid's names are plain names (not refused by
    # nav-gym-train's run_name, as they were between issue 31's check and this test)
    from nav_gym.training.config import TrainConfig
    grid = {'world': ['rooms.xml'], 'augment_colour': ['0', '0.2'], 'sim_params': ['{a: 1}']}
    for name, config in names(grid=grid, naming=NAMING):
        assert TrainConfig(run_name=name).run_name == name
        assert TrainConfig(run_name=config).run_name == config


@pytest.mark.parametrize(('exit_code', 'returned', 'evaluated'), [
    (0, 0, True), (None, 0, True), (130, 130, False), (1, 1, False), ('bad', 1, False)])
def test_a_trial_child_evaluates_only_after_a_finished_training(monkeypatch, exit_code,
                                                                returned, evaluated):
    from nav_eval.sweeps import trial as sweep_trial
    from nav_gym.training import trainer
    calls = []

    def run_training(args):  # nav-gym-train's body, as the trial calls it
        calls.append(('train', args.seed))
        raise SystemExit(exit_code)

    monkeypatch.setattr(trainer, 'run_training', run_training)
    monkeypatch.setattr(sweep_trial, 'train_args', lambda trial: ['--seed', '1'])
    monkeypatch.setattr(sweep_trial, 'evaluate_trial', lambda trial: calls.append(('evaluate',)))
    assert sweep_trial.train_and_evaluate({'name': 'seed1'}) == returned
    assert calls == [('train', '1')] + ([('evaluate',)] if evaluated else [])


def test_a_trial_gets_a_cpu_per_sim_and_one_for_the_learner_unless_told():
    from nav_eval.sweeps.spec import SweepSpec, trial_cpus
    assert trial_cpus({}, {}) == SweepSpec.cpus_per_trial == 2
    assert trial_cpus({'n_envs': '4'}, {}) == 5
    assert trial_cpus({}, {'n_envs': ['1', '8', '2']}) == 9
    assert trial_cpus({'n_envs': '1'}, {}) == 2
    assert trial_cpus({'n_envs': 'many'}, {}) == 2  # the settings' check names the bad value


def test_a_trial_name_too_long_for_a_run_name_is_refused_before_anything_is_written(tmp_path):
    from nav_eval.errors import SweepError
    from nav_eval.sweep import build_parser
    from nav_eval.sweeps.spec import spec_from_args
    long_rate = '0.0001' + '0' * 110 + '1'  # a configuration name cut at its 120 characters
    args = build_parser().parse_args(['--storage', str(tmp_path), '--name', 'long', '--grid',
                                      f'learning_rate={long_rate},0.0002', '--seeds',
                                      '1,4000000000', '--no-baselines'])
    with pytest.raises(SweepError, match=r'a trial name must be .*: shorten the --set or --grid'):
        spec_from_args(args)
    assert not (tmp_path / 'long').exists()


def test_grid_points_that_share_a_name_once_cut_are_refused(tmp_path):
    from nav_eval.errors import SweepError
    from nav_eval.sweeps.spec import MAX_NAME, SweepSpec
    prefix = '0.' + '0' * (MAX_NAME - len('learning_rate=0.'))
    spec = SweepSpec(sweep_dir=str(tmp_path), seeds=[1],
                     grid={'learning_rate': [prefix + '1', prefix + '2']})
    with pytest.raises(SweepError, match=r'both named .* first 120 characters'):
        spec.configurations()
    spec.grid['learning_rate'] = ['0.0001', '0.0001']
    with pytest.raises(SweepError, match='a repeated value'):
        spec.configurations()
    spec.grid['learning_rate'] = ['0.0001', '0.0002']
    assert [n for n, _ in spec.configurations()] == ['learning_rate=0.0001',
                                                     'learning_rate=0.0002']


def test_a_summary_whose_settings_do_not_load_here_groups_by_them_as_saved(tmp_path, capsys):
    from nav_eval.sweeps.collect import exported_dirs, read_exported
    row = {'config': 'c', 'trial': 'seed1', 'seed': 1, 'steps': 50000, 'wall_clock_s': 1.5,
           **{f'{split}_{rate}': 0.5 for split in ('train', 'heldout')
              for rate in ('success_rate', 'collision_rate', 'timeout_rate', 'mean_spl')},
           'train_episodes': 2, 'heldout_episodes': 2}
    (tmp_path / 's').mkdir()
    (tmp_path / 's' / 'results.json').write_text(json.dumps(
        {'per_seed': [row, dict(row)], 'settings': {'c': {'learning_rate': -1.0}}}))
    trials = read_exported(exported_dirs(tmp_path))
    assert [t['name'] for t in trials] == ['s:seed1']  # the same trial twice: once
    # the values of its time (run_settings) fill what it does not name
    assert trials[0]['settings'] == {'learning_rate': -1.0, **LEGACY_DEFAULTS}
    assert 's: the settings of c do not load here' in capsys.readouterr().out
