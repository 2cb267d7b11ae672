"""One controlling client per sim, every reset of a burst answered, and observers never refused."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import SimpleNamespace

from rclpy.executors import SingleThreadedExecutor
from sensor_msgs.msg import Image
from std_msgs.msg import String
from std_srvs.srv import Trigger

from helpers import interrupt, wait_until
from nav_sim import interface
from nav_sim.errors import SimInUseError
from nav_sim.ros import claim, qos
from nav_sim.ros.bare import own_node
from nav_sim.ros.client import SimClient
from nav_sim.ros.process import SimProcess
from nav_sim.ros.sim_graph import UNKNOWN_NODE

TRAIN = str(Path(sys.prefix) / 'bin' / 'nav-gym-train')


class Trainers:
    """Training runs attached to one sim, each writing to files.

    Never to a pipe that nobody reads while it trains, so that a failed wait can say what each
    run was doing.
    """

    def __init__(self, tmp_path: Path, namespace: str, sim: SimProcess) -> None:
        self.tmp_path, self.namespace, self.sim = tmp_path, namespace, sim
        self.runs: dict[str, subprocess.Popen] = {}
        self.codes: dict[str, int] = {}  # the exit codes, once stopped

    def files(self, name: str) -> tuple[Path, Path]:
        return self.tmp_path / f'{name}.out', self.tmp_path / f'{name}.err'

    def start(self, name: str, *settings: str) -> subprocess.Popen:
        out, err = self.files(name)
        with out.open('w') as stdout, err.open('w') as stderr:
            self.runs[name] = subprocess.Popen(
                [TRAIN, '--sim', 'attach', '--namespace', self.namespace, '--runs-dir',
                 str(self.tmp_path), '--run-name', name, '--buffer-size', '500',
                 '--sim-timeout', '30', *settings], stdout=stdout, stderr=stderr, text=True)
        return self.runs[name]

    def output(self, name: str) -> str:
        return ''.join(path.read_text() for path in self.files(name) if path.exists())

    def report(self) -> str:
        """Each run's state, the end of its output and the sim's log: what a failed wait says."""
        lines = []
        for name, run in self.runs.items():
            state = 'running' if run.poll() is None else f'exit {run.returncode}'
            out, err = (p.read_text()[-2000:] if p.exists() else '' for p in self.files(name))
            lines.append(f'{name}: {state}\n  stdout: {out!r}\n  stderr: {err!r}')
        lines.append(f'sim: {self.sim.output()[-3000:]!r}')  # its claims and holders
        return '\n'.join(lines)

    def stop(self) -> dict[str, int]:
        """Interrupt the runs still going (SIGINT: each saves a checkpoint); their exit codes."""
        return {name: interrupt(run, timeout=120)[0] if run.poll() is None else run.returncode
                for name, run in self.runs.items()}


LONG = ('--total-timesteps', '100000', '--learning-starts', '60', '--checkpoint-freq', '100000')


def refusal(trainers: Trainers, name: str) -> str:
    """Return the one line of a refused run's error output, checked."""
    (line,) = trainers.files(name)[1].read_text().strip().splitlines()
    assert line.startswith(f"nav-gym-train: error: the sim in namespace '{trainers.namespace}' "
                           'is in use:'), line
    assert 'one controlling client at a time' in line
    return line


@contextmanager
def trainers_on_a_sim(tmp_path: Path, namespace: str) -> Iterator[tuple[Trainers, Observer]]:
    """Start a sim, give trainers for it and an observer of it (a plain subscriber).

    On leaving, the observer closes, the runs still going are interrupted (every run's exit code
    in ``trainers.codes``) and the sim must be alive.
    """
    with SimProcess(namespace, {}) as sim:
        trainers = Trainers(tmp_path, namespace, sim)
        observer = Observer(namespace)
        try:
            yield trainers, observer
        finally:
            try:
                observer.close()
            finally:
                trainers.codes = trainers.stop()
        assert sim.alive()


def test_a_second_trainer_is_refused_at_once_while_the_first_trains_on(tmp_path, namespace):
    with trainers_on_a_sim(tmp_path, namespace) as (trainers, observer):
        first = trainers.start('first', *LONG)
        # an observer hears the sim all along, never refused
        observer.spin_until_holding(first, 120.0, 'the first run', trainers.report)
        assert first.poll() is None, trainers.report()
        started = time.monotonic()
        second = trainers.start('second', '--total-timesteps', '120')
        observer.spin_until(lambda: second.poll() is not None, 120.0, 'the second run',
                            trainers.report)
        refused_in = time.monotonic() - started
        # still heard, and the first run still steps the sim
        observer.spin_until_images(lambda: first.poll() is not None, 60.0,
                                   'the first run going on', trainers.report)
        still_training = first.poll() is None
        report = trainers.report()
    codes = trainers.codes
    assert codes['second'] == 1 and refused_in < 20.0, report
    refusal(trainers, 'second')
    output = trainers.output('first')
    assert still_training and codes['first'] == 130 and 'interrupted at step' in output, \
        f'{report}\n{output}'
    assert 'Traceback' not in output


def test_of_two_trainers_started_at_once_one_trains_and_the_other_is_refused(tmp_path,
                                                                             namespace):
    # their claims are stamped and heard in either order: never both granted
    with trainers_on_a_sim(tmp_path, namespace) as (trainers, observer):
        runs = [trainers.start('a', *LONG), trainers.start('b', *LONG)]
        observer.spin_until(lambda: any(run.poll() is not None for run in runs), 120.0,
                            'one of the two runs refused', trainers.report)
        (going,) = [run for run in runs if run.poll() is None] or [None]
        assert going is not None, trainers.report()
        observer.spin_until_holding(going, 60.0, 'the other run', trainers.report)
        still_training = going.poll() is None
        report = trainers.report()
    codes = trainers.codes
    refused, kept = ('a', 'b') if codes['a'] == 1 else ('b', 'a')
    assert codes[refused] == 1 and codes[kept] == 130 and still_training, report
    refusal(trainers, refused)
    assert 'interrupted at step' in trainers.output(kept), report


class Graph:
    """The parts of an rclpy node that the sim's claim arbiter uses, its graph set by hand."""

    def __init__(self) -> None:
        self.publishers: list[SimpleNamespace] = []  # of the claim topic, as the rmw shows them
        self.deliver = None  # the arbiter's claim callback
        self.log: list[str] = []  # what the arbiter logged
        self.answers: list[dict] = []  # what it published on the controller topic

    def create_publisher(self, *args) -> SimpleNamespace:
        return SimpleNamespace(publish=lambda msg: self.answers.append(json.loads(msg.data)))

    def create_subscription(self, msg_type, topic, callback, qos_profile) -> None:
        self.deliver = lambda claim_: callback(String(data=json.dumps(claim_)))

    def create_timer(self, *args) -> None:
        return None

    def resolve_topic_name(self, name: str) -> str:
        return f'/ns/{name}'

    def get_publishers_info_by_topic(self, topic: str) -> list[SimpleNamespace]:
        return list(self.publishers)

    def get_logger(self) -> SimpleNamespace:
        return SimpleNamespace(info=self.log.append)


UNNAMED = SimpleNamespace(node_name=UNKNOWN_NODE, node_namespace='_NODE_NAMESPACE_UNKNOWN_')


def named(name: str) -> SimpleNamespace:
    return SimpleNamespace(node_name=name, node_namespace='/ns')


def arbiter_at(monkeypatch, now: list[float]) -> tuple[claim.ClaimArbiter, Graph]:
    """Return a claim arbiter on a hand-set graph, its clock ``now[0]``, and the graph."""
    monkeypatch.setattr(claim, 'time', SimpleNamespace(monotonic=lambda: now[0]))
    graph = Graph()
    return claim.ClaimArbiter(graph), graph


def test_the_holders_claim_stands_while_discovery_has_not_named_its_node(monkeypatch):
    now = [1000.0]
    arbiter, graph = arbiter_at(monkeypatch, now)
    first = {'node': '/ns/first', 'host': 'h', 'pid': 1, 'since_ns': 1}
    # the probe sees a drop: a claim whose publisher the graph never shows falls after FRESH_S
    graph.deliver(first)
    assert arbiter.holder == first
    now[0] += claim.FRESH_S + 1
    arbiter.update()
    assert arbiter.holder is None
    assert graph.log[-2:] == ['the claim of /ns/first (process 1) ended: the graph did not name '
                              'its node within 6 s', 'held by no client']

    # on a loaded machine the graph shows the endpoint before it names its node: the holder's
    # claim stands, and a second client is refused meanwhile
    graph.publishers = [UNNAMED]
    graph.deliver(first)
    now[0] += claim.FRESH_S + 1
    arbiter.update()
    assert arbiter.holder == first
    graph.deliver({'node': '/ns/second', 'host': 'h', 'pid': 2, 'since_ns': 2})
    assert arbiter.holder == first
    graph.publishers = [UNNAMED, named('first')]
    arbiter.update()
    assert arbiter.holder == first
    # ... and falls at once when its named publisher goes (its client has closed)
    graph.publishers = [UNNAMED]
    arbiter.update()
    assert arbiter.holder['node'] == '/ns/second'
    assert 'the claim of /ns/first (process 1) ended: its node left the graph' in graph.log
    # an endpoint that is never named holds the sim no longer than SETTLE_S
    now[0] += claim.SETTLE_S
    arbiter.update()
    assert arbiter.holder is None


def test_a_refused_claim_never_stands_in_for_a_holder_that_has_gone(monkeypatch):
    now = [1000.0]
    arbiter, graph = arbiter_at(monkeypatch, now)
    holder = {'node': '/ns/holder', 'host': 'h', 'pid': 1, 'since_ns': 1}
    graph.publishers = [named('holder')]
    graph.deliver(holder)
    # a late client is refused and withdraws before the graph names it
    graph.publishers = [named('holder'), UNNAMED]
    graph.deliver({'node': '/ns/late', 'host': 'h', 'pid': 2, 'since_ns': 2})
    assert arbiter.holder == holder
    graph.publishers = [named('holder')]
    now[0] += claim.FRESH_S + 1
    # the holder goes, and the next client claims while the graph has not named it yet
    graph.publishers = [UNNAMED]
    graph.deliver({'node': '/ns/next', 'host': 'h', 'pid': 3, 'since_ns': 3})
    assert arbiter.holder['node'] == '/ns/next'


def test_a_holder_keeps_the_sim_when_a_claim_stamped_earlier_is_heard_after_it(monkeypatch):
    # two trainers started at once: the one stamped first may be heard second, after the other
    # was told that it holds the sim and began to step it
    arbiter, graph = arbiter_at(monkeypatch, [1000.0])
    graph.publishers = [named('first'), named('second')]
    first = {'node': '/ns/first', 'host': 'h', 'pid': 1, 'since_ns': 20}
    second = {'node': '/ns/second', 'host': 'h', 'pid': 2, 'since_ns': 10}
    graph.deliver(first)
    assert graph.answers[-1] == {**first, 'heard': [['/ns/first', 'h', 1, 20]]}
    assert claim.settles(graph.answers[-1], first)
    assert not claim.settles(graph.answers[-1], second)  # not heard yet: the second waits
    graph.deliver(second)
    assert arbiter.holder == first
    assert graph.answers[-1]['node'] == '/ns/first'
    assert claim.settles(graph.answers[-1], second)  # heard, and not the holder: refused
    # the holder claims again (a later stamp) and still holds; the holder changed once.  An
    # answer that has not heard the new claim does not settle it
    again = {**first, 'since_ns': 30}
    assert not claim.settles(graph.answers[-1], again)
    graph.deliver(again)
    assert arbiter.holder == again and claim.settles(graph.answers[-1], again)
    assert [line for line in graph.log if line.startswith('held by')] == [
        'held by no client', 'held by /ns/first (process 1)']
    # a free sim goes to the earliest claim heard
    graph.publishers = [named('second')]
    arbiter.update()
    assert arbiter.holder == second


def test_clients_of_two_processes_with_one_node_name_are_two_claims(monkeypatch):
    arbiter, graph = arbiter_at(monkeypatch, [1000.0])
    graph.publishers = [named('visnav_closed_loop'), named('visnav_closed_loop')]
    first = {'node': '/ns/visnav_closed_loop', 'host': 'h', 'pid': 1, 'since_ns': 1}
    graph.deliver(first)
    graph.deliver({**first, 'pid': 2, 'since_ns': 2})
    assert arbiter.holder == first  # so the second process is refused


class Observer:
    """A plain rclpy subscriber of the sim's camera and of its answer to the claims."""

    def __init__(self, namespace: str) -> None:
        self.context, self.node = own_node('observer', namespace)
        self.images = 0
        self.holder: dict = {}  # the sim's answer to the claims (nav_sim.ros.claim)
        self.node.create_subscription(Image, interface.IMAGE_TOPIC, self._on_image,
                                      qos.OBSERVATION)
        self.node.create_subscription(
            String, interface.CONTROLLER_TOPIC,
            lambda msg: setattr(self, 'holder', json.loads(msg.data)), qos.LATCHED)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def _on_image(self, msg: Image) -> None:
        self.images += 1

    def spin_until(self, done, timeout: float, what: str, details=None) -> None:
        def spun():
            self.executor.spin_once(timeout_sec=0.02)
            return done()
        wait_until(spun, timeout, what, interval=0, details=details)

    def spin_until_images(self, ended, timeout: float, what: str, details=None) -> None:
        """Spin until an image comes after those heard so far, or ``ended()`` holds."""
        images = self.images
        self.spin_until(lambda: self.images > images or ended(), timeout, what, details)

    def spin_until_holding(self, run: subprocess.Popen, timeout: float, what: str,
                           details=None) -> None:
        """Spin until the sim's answer names ``run``'s process, then until it steps the sim.

        An image after the answer says that it steps the sim (the sim's first image, of its
        initial reset, may come before any claim).  Either wait ends early if ``run`` ends.
        """
        self.spin_until(lambda: self.holder.get('pid') == run.pid or run.poll() is not None,
                        timeout, f'{what} holding the sim', details)
        self.spin_until_images(lambda: run.poll() is not None, 60.0,
                               f'{what} stepping the sim', details)

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
