"""One controlling client per sim, every reset of a burst answered, and observers never refused."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from rclpy.executors import SingleThreadedExecutor
from sensor_msgs.msg import Image
from std_srvs.srv import Trigger

from helpers import interrupt, wait_until
from nav_sim import interface
from nav_sim.errors import SimInUseError
from nav_sim.ros import qos
from nav_sim.ros.bare import own_node
from nav_sim.ros.client import SimClient
from nav_sim.ros.process import SimProcess

TRAIN = str(Path(sys.prefix) / 'bin' / 'nav-gym-train')


def test_a_second_trainer_is_refused_at_once_while_the_first_trains_on(tmp_path, namespace):
    with SimProcess(namespace, {}) as sim:
        observer = Observer(namespace)
        first = second = None
        try:
            first = subprocess.Popen(
                [TRAIN, '--sim', 'attach', '--namespace', namespace, '--runs-dir',
                 str(tmp_path), '--run-name', 'first', '--total-timesteps', '100000',
                 '--learning-starts', '60', '--checkpoint-freq', '100000', '--buffer-size',
                 '500', '--sim-timeout', '30'],
                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            # an observer (a plain subscriber) hears the sim all along, never refused.  A
            # lockstep sim publishes only when its client steps it: the first image says the
            # first run holds the sim (its claim comes before its first step)
            observer.spin_until(lambda: observer.images > 0 or first.poll() is not None, 120.0,
                                'the first run stepping the sim')
            started = time.monotonic()
            second = subprocess.Popen(
                [TRAIN, '--sim', 'attach', '--namespace', namespace, '--runs-dir',
                 str(tmp_path), '--run-name', 'second', '--total-timesteps', '120',
                 '--buffer-size', '500', '--sim-timeout', '30'], stdout=subprocess.PIPE,
                stderr=subprocess.PIPE, text=True)
            observer.spin_until(lambda: second.poll() is not None, 120.0, 'the second run')
            refused_in = time.monotonic() - started
            second_err = second.communicate(timeout=60)[1]
            images = observer.images  # still heard, and the first run still steps the sim
            observer.spin_until(lambda: observer.images > images, 60.0, 'the first run going on')
            still_training = first.poll() is None
        finally:
            try:
                observer.close()
            finally:
                if second is not None and second.poll() is None:
                    interrupt(second, timeout=30)
                if first is not None:
                    code, output = interrupt(first, timeout=120)
        assert sim.alive()
    assert second.returncode == 1 and refused_in < 20.0, second_err
    (line,) = second_err.strip().splitlines()
    assert line.startswith(f"nav-gym-train: error: the sim in namespace '{namespace}' is in "
                           'use:'), line
    assert 'one controlling client at a time' in line
    # the observer heard images before the second run and after its refusal (the waits above)
    assert still_training and code == 130 and 'interrupted at step' in output, output
    assert 'Traceback' not in output


class Observer:
    """A plain rclpy subscriber of the sim's camera."""

    def __init__(self, namespace: str) -> None:
        self.context, self.node = own_node('observer', namespace)
        self.images = 0
        self.node.create_subscription(Image, interface.IMAGE_TOPIC, self._on_image,
                                      qos.OBSERVATION)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def _on_image(self, msg: Image) -> None:
        self.images += 1

    def spin_until(self, done, timeout: float, what: str) -> None:
        def spun():
            self.executor.spin_once(timeout_sec=0.02)
            return done()
        wait_until(spun, timeout, what, interval=0)

    def close(self) -> None:
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self.context.try_shutdown()


HOLDER = """
import sys, time
from nav_sim.ros.client import SimClient
client = SimClient(sys.argv[1], timeout=15.0, node_name='holder')
client.wait_for_sim(30.0)
print('claimed', flush=True)
time.sleep(600)
"""


def test_a_killed_client_releases_the_sim_within_the_lease(namespace):
    with SimProcess(namespace, {}):
        holder = subprocess.Popen([sys.executable, '-c', HOLDER, namespace],
                                  stdout=subprocess.PIPE, text=True)
        try:
            assert holder.stdout.readline().strip() == 'claimed'
            with SimClient(namespace, timeout=15.0, node_name='late') as late:
                try:
                    late.wait_for_sim(30.0)
                    raise AssertionError('a second process claimed a held sim')
                except SimInUseError as exc:
                    assert f'{namespace}/holder (process {holder.pid}' in str(exc)
            # the same process may hold several clients (the checklist's second env)
            os.kill(holder.pid, signal.SIGKILL)
            holder.wait()
            killed = time.monotonic()

            def claimed() -> bool:
                with SimClient(namespace, timeout=15.0, node_name='next') as client:
                    try:
                        client.wait_for_sim(30.0)
                        return True
                    except SimInUseError:
                        return False
            wait_until(claimed, 30.0, 'the sim released after its holder was killed',
                       interval=0.5)
            assert time.monotonic() - killed < 25.0  # Fast DDS's lease: 20 s
        finally:
            if holder.poll() is None:
                holder.kill()
                holder.wait()


def test_clients_of_one_process_share_the_claim(namespace):
    with SimProcess(namespace, {}), SimClient(namespace, timeout=15.0) as first, \
            SimClient(namespace, timeout=15.0, node_name='second') as second:
        first.wait_for_sim(30.0)
        second.wait_for_sim(30.0)
        assert first.claim.held and second.claim.held


def test_every_reset_of_a_burst_is_answered(namespace):
    with SimProcess(namespace, {}):
        context, node = own_node('burst', namespace)
        try:
            # a foreign client with a deep response queue: what it sends, the sim answers
            client = node.create_client(Trigger, interface.RESET_SERVICE,
                                        qos_profile=qos.SERVICE_REQUESTS)
            assert client.wait_for_service(timeout_sec=30.0)
            executor = SingleThreadedExecutor(context=context)
            executor.add_node(node)
            futures = [client.call_async(Trigger.Request()) for _ in range(300)]

            def answered() -> int:
                executor.spin_once(timeout_sec=0.05)
                return sum(f.done() for f in futures)
            wait_until(lambda: answered() == 300, 120.0, 'answers to all 300 resets',
                       interval=0, details=lambda: f'{answered()} of 300 answered')
            assert all(f.result().success for f in futures)
        finally:
            node.destroy_node()
            context.try_shutdown()


def test_a_sim_that_dies_before_it_answers_the_claim_is_named_at_once(namespace):
    """No sim answers in this namespace: only ``abort`` (a dead sim process) ends the wait."""
    import pytest

    from nav_sim.errors import SimUnavailableError
    client = SimClient(namespace, timeout=5.0)
    try:
        start = time.monotonic()  # the probe: without abort, the claim waits for its time-out
        with pytest.raises(SimUnavailableError, match='did not answer its claim within 0.5 s'):
            client.claim.acquire(lambda t: client.spin_once(t), client.where, 0.5)
        assert time.monotonic() - start >= 0.5
        polls = []

        def abort() -> str | None:
            polls.append(1)
            return 'sim_node (pid 1) was killed by signal SIGKILL (9)' if len(polls) > 2 else None
        start = time.monotonic()
        with pytest.raises(SimUnavailableError) as raised:
            client.claim.acquire(lambda t: client.spin_once(t), client.where, 60.0, abort)
        assert str(raised.value) == (f'nav_sim in {client.where} stopped before it answered '
                                     'its claim: sim_node (pid 1) was killed by signal SIGKILL '
                                     '(9)')
        assert time.monotonic() - start < 5.0 and not client.claim.held
    finally:
        client.close()
