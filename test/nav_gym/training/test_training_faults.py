"""Training under faults, as a user meets them.

Ctrl-C during the final save, a full disk, the trainer's own sim killed, an unwritable or
unreadable run directory.
"""

from __future__ import annotations

import errno
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from helpers import reported_as_another_error, wait_until
from nav_gym.errors import DiskFullError
from nav_gym.training import trainer as train
from nav_gym.training.run_dir import checkpoints

TINY = ['--learning-starts', '100', '--buffer-size', '500', '--sim', 'embedded']


class Output:
    """The lines a child process prints, collected by a thread; wait for one with a deadline."""

    def __init__(self, stream) -> None:
        self.lines: list[str] = []
        self._thread = threading.Thread(target=self._read, args=(stream,), daemon=True)
        self._thread.start()

    def _read(self, stream) -> None:
        for line in stream:
            self.lines.append(line)

    def wait_for(self, text: str, process: subprocess.Popen, timeout: float = 240,
                 errors: Output | None = None) -> None:
        def printed() -> bool:
            if any(text in line for line in self.lines):
                return True
            if process.poll() is not None:
                pytest.fail(f'exited {process.returncode}: {self.text}'
                            f'{errors.text if errors else ""}')
            return False

        wait_until(printed, timeout, f'{text!r} printed', interval=0.05,
                   details=lambda: self.text)

    @property
    def text(self) -> str:
        self._thread.join(0.5)
        return ''.join(self.lines)


def start_training(args: list[str], env: dict[str, str] | None = None
                   ) -> tuple[subprocess.Popen, Output, Output]:
    process = subprocess.Popen([sys.executable, '-m', 'nav_gym.train', *args],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               env={**os.environ, **(env or {})})
    return process, Output(process.stdout), Output(process.stderr)


def finish(process: subprocess.Popen, timeout: float = 180) -> int:
    try:
        return process.wait(timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()
        raise


def interrupt_while_writing(tmp: Path, process: subprocess.Popen, out: Output,
                            err: Output) -> None:
    """Press Ctrl-C on the trainer in the middle of writing ``tmp`` (an atomic write's temp file).

    ``tmp`` is made a named pipe before the trainer writes it: the trainer's write blocks
    until this test reads, and blocks again once the pipe is full, so the SIGINT lands while
    the file is half written (the bytes read prove it).  The pipe is then drained to its end,
    so that closing the half-written file never blocks the trainer, and never fails (a pipe
    closed by its reader would fail the write with EPIPE instead).
    """
    wait_until(lambda: tmp.parent.is_dir() or process.poll() is not None, 240,
               f'{tmp.parent} created', details=lambda: out.text + err.text)
    os.mkfifo(tmp)
    with open(tmp, 'rb') as pipe:  # blocks until the trainer opens the file to write it
        assert pipe.read(4096), 'the trainer wrote nothing'
        assert process.poll() is None
        process.send_signal(signal.SIGINT)
        while pipe.read(1 << 16):
            pass

def test_only_the_first_sigterm_stops_a_run_so_a_second_cannot_cut_its_save():
    """A sweep's trial gets SIGTERM more than once as Ray's processes end; the first counts.

    The second used to land in the middle of the checkpoint the stopping run saved (R1 lost
    its newest progress twice so): it is ignored now, and the save completes.
    """
    from nav_gym.cli import stop_on_sigterm
    previous = signal.getsignal(signal.SIGTERM)
    try:
        stop_on_sigterm()
        with pytest.raises(KeyboardInterrupt):  # the first: stop as Ctrl-C does
            os.kill(os.getpid(), signal.SIGTERM)
            time.sleep(5)
        os.kill(os.getpid(), signal.SIGTERM)  # the second, while the run saves: nothing
        time.sleep(0.2)
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGTERM, previous)


def temporary_files(run_dir: Path) -> list[Path]:
    return [p for p in run_dir.rglob('*') if p.name.endswith('.tmp')]


def buffer_step(run_dir: Path) -> int | None:
    marker = run_dir / 'checkpoints' / 'replay_buffer.step'
    return int(marker.read_text()) if marker.is_file() else None


def test_ctrl_c_while_writing_the_final_model_leaves_a_resumable_run(tmp_path):
    run_dir = tmp_path / 'final'
    process, out, err = start_training(
        ['--total-timesteps', '200', '--checkpoint-freq', '100', *TINY, '--runs-dir',
         str(tmp_path), '--run-name', 'final'])
    interrupt_while_writing(run_dir / '.final_model.zip.tmp', process, out, err)
    assert finish(process) == 130, out.text + err.text
    assert f'continue with: nav-gym-train --resume {run_dir}' in out.text
    assert 'Traceback' not in err.text
    assert temporary_files(run_dir) == []
    assert not (run_dir / 'final_model.zip').exists()
    # the checkpoint of the last step, with its replay buffer, is there to resume from
    assert checkpoints(run_dir)[-1][0] == 200 and buffer_step(run_dir) == 200

    resumed = subprocess.run([sys.executable, '-m', 'nav_gym.train', '--resume', str(run_dir)],
                             capture_output=True, text=True, timeout=240)
    assert resumed.returncode == 0, resumed.stdout + resumed.stderr
    assert 'with its replay buffer' in resumed.stdout and '0 steps remain' in resumed.stdout
    assert (run_dir / 'final_model.zip').is_file() and (run_dir / 'summary.json').is_file()
    # a finished run deletes its replay buffer (only resume needs it)
    assert not (run_dir / 'checkpoints' / 'replay_buffer.pkl').exists()
    assert buffer_step(run_dir) is None and temporary_files(run_dir) == []
    # the last checkpoint is the final model's file, not a 27 MB copy
    assert os.path.samefile(run_dir / 'final_model.zip', checkpoints(run_dir)[-1][1])


def test_ctrl_c_while_keeping_the_replay_buffer_at_the_end(tmp_path):
    """The final model and summary are written before the (large) replay buffer."""
    run_dir = tmp_path / 'keep'
    process, out, err = start_training(
        ['--total-timesteps', '150', '--checkpoint-freq', '1000', *TINY, '--runs-dir',
         str(tmp_path), '--run-name', 'keep', '--keep-replay-buffer', 'true'])
    interrupt_while_writing(run_dir / 'checkpoints' / '.replay_buffer.pkl.tmp', process, out,
                            err)
    assert finish(process) == 130, out.text + err.text
    assert 'the run is complete' in out.text and '--resume' in out.text
    assert 'Traceback' not in err.text
    assert (run_dir / 'final_model.zip').is_file() and (run_dir / 'summary.json').is_file()
    assert temporary_files(run_dir) == []
    assert not (run_dir / 'checkpoints' / 'replay_buffer.pkl').exists()
    assert buffer_step(run_dir) is None  # no marker without its buffer


def trainer_children(pid: int) -> list[int]:
    found = []
    for task in Path(f'/proc/{pid}/task').iterdir():
        text = (task / 'children').read_text().split()
        found += [int(p) for p in text]
    return found


def test_a_killed_embedded_sim_saves_a_checkpoint_and_says_how_to_resume(tmp_path):
    run_dir = tmp_path / 'killed'
    process, out, err = start_training(
        ['--total-timesteps', '100000', '--checkpoint-freq', '100000', '--learning-starts', '50',
         '--buffer-size', '1000', '--sim', 'embedded', '--runs-dir', str(tmp_path),
         '--run-name', 'killed'])
    monitor = run_dir / 'monitor.csv'

    def learning() -> bool:  # two episodes in the Monitor CSV
        if monitor.is_file() and len(monitor.read_text().splitlines()) > 2:
            return True
        assert process.poll() is None, out.text + err.text
        return False

    wait_until(learning, 240, 'two episodes in the Monitor CSV', interval=0.1,
               details=lambda: out.text + err.text)
    sims = [pid for pid in trainer_children(process.pid)
            if b'sim_node' in Path(f'/proc/{pid}/cmdline').read_bytes()]
    assert len(sims) == 1
    os.kill(sims[0], signal.SIGKILL)
    assert finish(process) == 1, out.text + err.text
    errors = err.text.strip().splitlines()
    assert len(errors) == 1 and 'Traceback' not in err.text, err.text
    assert 'the embedded sim died (sim_node (pid ' in errors[0]
    assert 'was killed by signal SIGKILL (9)' in errors[0]
    assert f'continue with: nav-gym-train --resume {run_dir}' in errors[0]
    steps = checkpoints(run_dir)[-1][0]
    assert steps > 0 and buffer_step(run_dir) == steps
    assert (run_dir / 'checkpoints' / 'replay_buffer.pkl').is_file()
    assert temporary_files(run_dir) == []


def test_a_ctrl_c_reported_as_another_error_saves_a_checkpoint_as_ctrl_c_does(
        tmp_path, namespace, monkeypatch, capsys):
    # the race CI hit (2026-11-29): the Ctrl-C came out of rclpy's take_response as
    # "SystemError: ... returned a result with an exception set", its cause the interrupt, and
    # the run failed (exit 1) instead of stopping as Ctrl-C does
    from stable_baselines3.common.callbacks import BaseCallback

    from nav_gym.training import config as train_config

    class ReportedAsAnotherError(BaseCallback):
        def _on_step(self) -> bool:
            if self.num_timesteps == 30:
                raise reported_as_another_error()
            return True

    monkeypatch.setattr(train, 'training_callback', lambda env: ReportedAsAnotherError())
    config = train_config.build(None, {'sim': 'embedded', 'namespace': namespace,
                                       'learning_starts': 100, 'buffer_size': 500,
                                       'total_timesteps': 200, 'device': 'cpu'})
    run_dir = tmp_path / 'run'
    run_dir.mkdir()
    summary = train.train(config, run_dir)
    assert summary['outcome'] == 'interrupted' and summary['num_timesteps'] == 30
    assert f'interrupted at step 30: checkpoint {run_dir}' in capsys.readouterr().out
    assert checkpoints(run_dir)[-1][0] == 30 and buffer_step(run_dir) == 30


def no_space(*args, **kwargs):
    raise OSError(errno.ENOSPC, 'No space left on device')


def test_a_full_disk_is_a_one_line_error_and_leaves_no_temporary_file(tmp_path, spaces_only):
    from stable_baselines3 import DQN
    model = DQN('CnnPolicy', spaces_only(), buffer_size=100, learning_starts=10, device='cpu')
    model.learn(20)
    folder = tmp_path / 'checkpoints'
    folder.mkdir()
    train.write_text(folder / 'replay_buffer.step', '10')
    model.save_replay_buffer = no_space
    with pytest.raises(DiskFullError) as caught:
        train.save_replay_buffer(model, folder)
    message = str(caught.value)
    # 100 transitions x 2 observations x 3x84x84 bytes = 4.2 MB
    assert str(folder / 'replay_buffer.pkl') in message and 'about 4.2 MB' in message
    assert '\n' not in message
    assert list(folder.iterdir()) == []  # no temporary file; no marker for a buffer not written

    with pytest.raises(DiskFullError, match='final_model.zip: it needs more space'):
        train.atomic_write(tmp_path / 'final_model.zip', no_space)
    with pytest.raises(KeyboardInterrupt):
        train.atomic_write(tmp_path / 'summary.json', lambda handle: (handle.write(b'{'),
                                                                      no_interrupt()))
    assert sorted(p.name for p in tmp_path.iterdir()) == ['checkpoints']


def no_interrupt():
    raise KeyboardInterrupt


def command(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'nav_gym.train', *args], capture_output=True,
                          text=True, timeout=120)


def test_an_unusable_run_directory_is_a_one_line_error(tmp_path):
    result = command('--runs-dir', '/dev/null/x', '--sim', 'embedded')
    assert result.returncode == 1 and 'Traceback' not in result.stderr
    (line,) = result.stderr.strip().splitlines()
    assert line.startswith('nav-gym-train: error: cannot create the run directory /dev/null/x/')
    assert line.endswith('(Not a directory); choose another --runs-dir')

    run_dir = tmp_path / 'binary'
    run_dir.mkdir()
    (run_dir / 'config.yaml').write_bytes(bytes(range(256)) * 4)
    result = command('--resume', str(run_dir))
    assert result.returncode == 1 and 'Traceback' not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert 'not a UTF-8 text file' in result.stderr and 'config.yaml' in result.stderr


def test_a_run_stopped_before_its_first_checkpoint_resumes_from_step_zero(tmp_path):
    """Ctrl-C while the sim starts leaves only config.yaml: --resume still works."""
    from nav_gym.training.config import TrainConfig
    run_dir = tmp_path / 'early'
    run_dir.mkdir()
    (run_dir / 'config.yaml').write_text(TrainConfig(
        total_timesteps=40, learning_starts=100, buffer_size=500, sim='embedded').to_yaml())
    result = command('--resume', str(run_dir))
    assert result.returncode == 0, result.stdout + result.stderr
    assert 'has no checkpoint yet: training starts from step 0' in result.stdout
    assert (run_dir / 'final_model.zip').is_file()
