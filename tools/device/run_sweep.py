"""Run sweep directories' training trials at once, one thread each, without Ray.

    python tools/device/run_sweep.py runs/NAME [runs/NAME2 ...] [--stop-after SECONDS]

For one machine that has no Ray (a lent accelerator machine): each trial is the sweep's own
:func:`nav_eval.sweeps.trial.run_trial`, so its child, logs, checkpoints and evaluations are the
ones a Ray sweep writes, and ``visnav-sweep --aggregate`` or ``--resume`` reads them.  Baseline
trials are left out (make the sweep with ``--no-baselines``).  ``--stop-after``: SIGINT every
trial's child after that many seconds, so that each saves a checkpoint before an outer limit
kills it; running this again on that machine goes on from there.  A sweep packed without its
models (``screen.sh``) is for ``--aggregate`` only: ``visnav-sweep --resume`` would start its
trials afresh.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import threading
import time
from pathlib import Path

from nav_eval.sweeps.spec import load_spec
from nav_eval.sweeps.trial import run_trial, trial_finished

#: how long stopped trials get to save before the runner returns anyway
GRACE_SECONDS = 40
#: the exit code when no trial failed but some were stopped at --stop-after (run again)
STOPPED = 2


def main() -> int:
    """Run the sweeps' unfinished training trials; return 0 if all finished, 2 if stopped."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('sweep_dirs', type=Path, nargs='+', metavar='SWEEP_DIR')
    parser.add_argument('--stop-after', type=float, default=0)
    args = parser.parse_args()
    sweep_dirs = list(dict.fromkeys(d.resolve() for d in args.sweep_dirs))  # each once
    trials = [t for sweep_dir in sweep_dirs for t in load_spec(sweep_dir).trials()
              if t['kind'] == 'train' and not trial_finished(t)]
    results: dict[str, object] = {}
    lock = threading.Lock()
    stopping = threading.Event()
    start = time.monotonic()

    def one(trial: dict) -> None:
        figures: dict[str, object] = {}
        outcome: object = figures
        try:
            run_trial(trial, figures.update)
        except Exception as exc:  # noqa: BLE001 - reported with the trial's name
            outcome = ('STOPPED (saved; run again to go on)' if stopping.is_set()
                       else f'FAILED: {exc}')
        with lock:
            results[trial['run_dir']] = outcome  # names repeat across sweeps (seed1, ...)
            print(f"{time.monotonic() - start:7.1f} s {trial['run_dir']}: {json.dumps(outcome)}",
                  flush=True)

    threads = [threading.Thread(target=one, args=(t,), daemon=True) for t in trials]
    names = ', '.join(str(d) for d in sweep_dirs)
    print(f'{len(threads)} trials of {names} at once', flush=True)
    for thread in threads:
        thread.start()
        time.sleep(0.5)  # their children start one at a time (fork beside threads)
    deadline = start + args.stop_after if args.stop_after else None
    while any(t.is_alive() for t in threads):
        if deadline and time.monotonic() > deadline:
            print(f'{time.monotonic() - start:7.1f} s: stopping the trials (they save)',
                  flush=True)
            stopping.set()
            _interrupt_children()
            for thread in threads:  # each saves a checkpoint, then its thread ends
                thread.join(max(0.0, deadline + GRACE_SECONDS - time.monotonic()))
            break
        time.sleep(2)
    with lock:
        outcomes = dict(results)
    finished = sum(isinstance(r, dict) for r in outcomes.values())
    failed = sum(str(r).startswith('FAILED') for r in outcomes.values())
    print(f'{time.monotonic() - start:.1f} s: {finished} of {len(trials)} finished, '
          f'{failed} failed', flush=True)
    if finished == len(trials):
        return 0
    return 1 if failed else STOPPED


def _interrupt_children() -> None:
    """SIGINT each trial's child (each runs in a session of its own)."""
    me = os.getpid()
    for proc in Path('/proc').iterdir():
        if not proc.name.isdigit():
            continue
        try:
            fields = (proc / 'stat').read_text().rsplit(')', 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == me:  # ppid: a trial's child
            os.kill(int(proc.name), signal.SIGINT)


if __name__ == '__main__':
    raise SystemExit(main())
