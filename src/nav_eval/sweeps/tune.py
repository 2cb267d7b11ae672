"""The Ray Tune side of a sweep: start or attach Ray, run the trials, report progress.

Tune does the scheduling (a grid of trial dicts), the placement (``with_resources``: the trial's
CPUs and GPUs), the retries (``FailureConfig(max_failures=1)``) and the resumption
(``Tuner.restore`` of ``SWEEP_DIR/tune``).  Locally, Ray starts with this machine's CPUs and no
dashboard and is shut down at the end; with ``--address`` the sweep attaches to a running
cluster and leaves it running.
"""

from __future__ import annotations

import logging
import os
import time
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ray import tune
from ray.tune.experiment import Trial
from ray.tune.schedulers import FIFOScheduler

from nav_eval.evaluation.sets import BASELINE_POLICIES
from nav_eval.sweeps.spec import TUNE
from nav_eval.sweeps.trial import log_tail, run_trial

MAX_FAILURES = 1


@dataclass
class Outcome:
    """What became of a sweep's trials."""

    finished: list[str] = field(default_factory=list)
    failed: dict[str, str] = field(default_factory=dict)
    attempts: dict[str, int] = field(default_factory=dict)
    interrupted: bool = False


def trainable(config: dict[str, Any]) -> None:
    """Run one trial (the Tune function trainable) on the node Ray placed it on."""
    import ray
    run_trial(config['trial'], tune.report, node=ray.util.get_node_ip_address())


def _name(trial: Any) -> str:
    return trial.config['trial']['name']


def _percent(value: Any) -> str:
    return '–' if value is None else f'{100 * float(value):.0f}%'


class StartedFirst(FIFOScheduler):
    """Run the trials an earlier session started before those it never reached, each in order.

    Tune restores a sweep's trials in no set order (its state keeps them in a set) and its FIFO
    scheduler takes the first one pending: a resumed sweep would start a fresh trial while a
    half-trained one waited, and each stopped session would leave one more trial half done.
    A trial has started when its log exists; ties go by the sweep's order (``order``: names).
    """

    def __init__(self, order: list[str]) -> None:
        """Rank the trials by ``order`` (their names, in the sweep's order)."""
        super().__init__()
        self.rank = {name: i for i, name in enumerate(order)}

    def _key(self, trial: Any) -> tuple[bool, int]:
        spec = (trial.config or {}).get('trial') or {}
        started = bool(spec.get('log')) and Path(spec['log']).is_file()
        return not started, self.rank.get(spec.get('name'), len(self.rank))

    def choose_trial_to_run(self, tune_controller: Any) -> Any:
        """Return the pending (else paused) trial to run next: started ones first."""
        for status in (Trial.PENDING, Trial.PAUSED):
            ready = [t for t in tune_controller.get_trials() if t.status == status]
            if ready:
                return min(ready, key=self._key)
        return None


class ProgressLines(tune.Callback):
    """Print one line per trial start, retry, failure and end, with figures and the ETA."""

    def __init__(self, trials: list[dict[str, Any]], done: set[str] | frozenset = frozenset(),
                 ) -> None:
        """Follow ``trials`` (the trial dicts; their ``kind`` sets the ETA's durations).

        ``done``: names of trials that ended before (a resumed sweep's finished trials, and its
        failed ones when they are not run again); they count as done, once.
        """
        self.total = len(trials)
        self.ended_names = {t['name'] for t in trials} & set(done)
        todo = [t for t in trials if t['name'] not in self.ended_names]
        self.remaining = Counter(t['kind'] for t in todo)
        self.start = time.monotonic()
        self.started: dict[str, float] = {}
        self.durations: dict[str, list[float]] = {}
        self.results: dict[str, dict[str, Any]] = {}
        self.parallel = 1

    @property
    def ended(self) -> int:
        """How many trials have ended (finished or failed for good), this session or before."""
        return len(self.ended_names)

    def _line(self, text: str) -> None:
        elapsed = time.strftime('%H:%M:%S', time.gmtime(time.monotonic() - self.start))
        print(f'[{elapsed}] {text}', flush=True)

    def _first_end(self, trial: Any) -> bool:
        """Count a trial's end once; False for a trial that had ended before this session."""
        name = _name(trial)
        if name in self.ended_names:
            return False
        self.ended_names.add(name)
        return True

    def on_trial_start(self, iteration: int, trials: list, trial: Any, **info: Any) -> None:
        """Print that a trial (re)started."""
        self.started[_name(trial)] = time.monotonic()
        running = sum(1 for t in trials if t.status == 'RUNNING')
        self.parallel = max(self.parallel, running)
        self._line(f'start {_name(trial)} ({running} running, {self.ended} of {self.total} '
                   'done)')

    def on_trial_result(self, iteration: int, trials: list, trial: Any, result: dict,
                        **info: Any) -> None:
        """Keep a trial's headline figures for its end line."""
        self.results[_name(trial)] = result

    def on_trial_recover(self, iteration: int, trials: list, trial: Any, **info: Any) -> None:
        """Print that a failed trial will be retried."""
        self._line(f'retry {_name(trial)}: it failed, see {trial.config["trial"]["log"]}')

    def on_trial_error(self, iteration: int, trials: list, trial: Any, **info: Any) -> None:
        """Print that a trial failed for good."""
        if self._first_end(trial):
            self.remaining[trial.config['trial']['kind']] -= 1
        self._line(f'FAILED {_name(trial)} ({self.ended} of {self.total} done)')

    def on_trial_complete(self, iteration: int, trials: list, trial: Any, **info: Any) -> None:
        """Print a finished trial's headline figures and the sweep's ETA."""
        name = _name(trial)
        took = time.monotonic() - self.started.get(name, self.start)
        kind = trial.config['trial']['kind']
        if self._first_end(trial):  # a trial done before re-runs nothing: not a duration
            self.durations.setdefault(kind, []).append(took)
            self.remaining[kind] -= 1
        r = self.results.get(name, {})
        if kind == 'baseline':
            figures = ', '.join(f"{policy} {_percent(r.get(f'{policy}_train_success'))} / "
                                f"{_percent(r.get(f'{policy}_heldout_success'))}"
                                for policy in BASELINE_POLICIES) + ' (training / held-out)'
        else:
            figures = (f"held-out success {_percent(r.get('heldout_success'))} (collisions "
                       f"{_percent(r.get('heldout_collision'))}), training "
                       f"{_percent(r.get('train_success'))}")
        eta = eta_text(self.durations, self.remaining, self.parallel)
        self._line(f'done  {name} in {took:.0f} s: {figures}; {self.ended} of {self.total} '
                   f'done, ETA {eta}')


class AfterEachTrial(tune.Callback):
    """Call ``action()`` after each trial that completes (the sweep's summary keeper).

    It runs in the driver, between Tune's steps, while the other trials go on.  An error in it
    is printed in one line and the sweep goes on: a summary is a copy, never a reason to stop.
    """

    def __init__(self, action: Callable[[], Any]) -> None:
        """Call ``action`` once per completed trial."""
        self.action = action

    def on_trial_complete(self, iteration: int, trials: list, trial: Any, **info: Any) -> None:
        """Run the action; print its error, if any, instead of raising it."""
        try:
            self.action()
        except Exception as exc:  # any failure of a copy must not stop the sweep
            print(f'after {_name(trial)}: {type(exc).__name__}: {exc}', flush=True)


def eta_text(durations: Mapping[str, list[float]], remaining: Mapping[str, int],
             parallel: int) -> str:
    """Estimate the time left: the remaining trials of each kind, in waves of ``parallel``.

    A training trial takes minutes to hours and a baseline trial seconds to minutes, so each
    kind is timed on its own: ``ceil(remaining / parallel)`` waves of its mean duration (a kind
    with no finished trial yet takes the mean of all).
    """
    left = {kind: n for kind, n in remaining.items() if n > 0}
    if not left:
        return '0 s'
    finished = [d for kind in durations for d in durations[kind]]
    if not finished:
        return '–'

    def mean(values: list[float]) -> float:
        return sum(values) / len(values)

    seconds = sum(-(-n // max(1, parallel)) * mean(durations.get(kind) or finished)
                  for kind, n in left.items())
    return time.strftime('%H:%M:%S', time.gmtime(seconds)) if seconds < 86_400 else \
        f'{seconds / 3600:.0f} h'


def start_ray(address: str | None) -> bool:
    """Attach to ``address`` or start a local Ray; return True if this call started it."""
    import ray
    os.environ.setdefault('RAY_CHDIR_TO_TRIAL_DIR', '0')  # trials use absolute paths
    os.environ.setdefault('RAY_USAGE_STATS_ENABLED', '0')
    os.environ.setdefault('TUNE_WARN_EXCESSIVE_EXPERIMENT_CHECKPOINT_SYNC_THRESHOLD_S', '60')
    # a stopped trial's trainer gets SIGTERM from its parent's death (PR_SET_PDEATHSIG) and saves
    # a checkpoint; Ray's default would SIGKILL it first and lose the steps since the last one
    os.environ.setdefault('RAY_kill_child_processes_on_worker_exit', 'false')
    # Ray runs workers (and so the trainers and sims they start) at nice 15 by default: on a
    # machine shared with anything else the trials then get a fraction of their CPUs
    os.environ.setdefault('RAY_worker_niceness', '0')
    os.environ.setdefault('RAY_AIR_NEW_OUTPUT', '0')  # verbose=0 then prints nothing
    # one trial staged at a time, the scheduler's (StartedFirst) choice: Tune would otherwise
    # stage every pending trial at once and start them in its restore order
    os.environ.setdefault('TUNE_MAX_PENDING_TRIALS_PG', '1')
    for name in ('ray.tune', 'ray.train', 'ray.air'):  # our progress lines say it all
        logging.getLogger(name).setLevel(logging.CRITICAL)
    if ray.is_initialized():
        return False
    if address:
        ray.init(address=address, log_to_driver=False, logging_level=logging.WARNING)
        return False
    ray.init(num_cpus=os.cpu_count(), include_dashboard=False, log_to_driver=False,
             logging_level=logging.WARNING)
    return True


def _tuner(spec: Any, trials: list[dict[str, Any]], resume: bool, retry_failed: bool,
           done: set[str] | frozenset, after_each: Callable[[], Any] | None = None,
           ) -> tuple[Any, ProgressLines]:
    resources = {'cpu': spec.cpus_per_trial, 'gpu': spec.gpus_per_trial}
    fn = tune.with_resources(trainable, resources)
    progress = ProgressLines(trials, done)
    callbacks: list[tune.Callback] = [progress]
    if after_each is not None:
        callbacks.append(AfterEachTrial(after_each))
    scheduler = StartedFirst([t['name'] for t in trials])
    path = str(Path(spec.sweep_dir) / TUNE)
    if resume and tune.Tuner.can_restore(path):
        tuner = tune.Tuner.restore(path, fn, resume_unfinished=True, resume_errored=False,
                                   restart_errored=retry_failed)
        # the restored configs hold the pickled callback and scheduler of the first session (or
        # none, for a sweep from before StartedFirst): fresh ones (Tuner.restore takes neither
        # config; this is its only handle)
        local = getattr(tuner, '_local_tuner', None)
        if local is not None and hasattr(local, '_run_config'):
            local._run_config.callbacks = callbacks
        if local is not None and hasattr(local, '_tune_config'):
            local._tune_config.scheduler = scheduler
        return tuner, progress
    run_config = tune.RunConfig(
        name=TUNE, storage_path=spec.sweep_dir, verbose=0, callbacks=callbacks,
        failure_config=tune.FailureConfig(max_failures=MAX_FAILURES),
        checkpoint_config=tune.CheckpointConfig(num_to_keep=1))
    tuner = tune.Tuner(fn, param_space={'trial': tune.grid_search(trials)},
                       tune_config=tune.TuneConfig(num_samples=1, reuse_actors=True,
                                                   trial_dirname_creator=_dirname,
                                                   scheduler=scheduler),
                       run_config=run_config)
    return tuner, progress


def _dirname(trial: Any) -> str:
    return _name(trial)


def run_trials(spec: Any, trials: list[dict[str, Any]], address: str | None, resume: bool,
               retry_failed: bool = False, done: set[str] | frozenset = frozenset(),
               after_each: Callable[[], Any] | None = None) -> Outcome:
    """Run the trials on Ray Tune and return which finished, failed or were interrupted.

    ``done``: the trials that ended in an earlier session (for the progress lines);
    ``after_each``: called after each trial that completes (:class:`AfterEachTrial`).
    """
    started = start_ray(address)
    try:
        tuner, _ = _tuner(spec, trials, resume, retry_failed, done, after_each)
        grid = tuner.fit()
        return _outcome(grid, trials)
    finally:
        if started:
            import ray
            ray.shutdown()


def _outcome(grid: Any, trials: list[dict[str, Any]]) -> Outcome:
    out = Outcome()
    seen = set()
    for result in grid:
        trial = (result.config or {}).get('trial')
        if trial is None:  # a trial Ctrl-C stopped before it started: Tune kept no config
            out.interrupted = True
            continue
        name = trial['name']
        seen.add(name)
        out.attempts[name] = _attempts(Path(trial['log']))
        if result.metrics and result.metrics.get('complete'):
            out.finished.append(name)
        elif result.error is not None:
            out.failed[name] = _error_text(result.error, Path(trial['log']))
        else:
            out.interrupted = True
    if len(seen) < len(trials):
        out.interrupted = True
    return out


def _attempts(log: Path) -> int:
    try:
        return log.read_text(errors='replace').count('\n# attempt at ')
    except OSError:
        return 0


def _error_text(error: BaseException, log: Path) -> str:
    text = str(error).strip().splitlines()
    cause = next((line for line in reversed(text) if 'Error' in line), text[-1] if text else '')
    return f'{cause.strip()}\n  log {log}, last lines:\n' + '\n'.join(
        f'    {line}' for line in log_tail(log).splitlines())
