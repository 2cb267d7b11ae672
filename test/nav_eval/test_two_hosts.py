"""Two hosts: the ROS graph and the Ray cluster across two Linux network namespaces.

Each namespace is a "host" with its own network stack, joined to the other by a veth pair
(10.X.Y.1 and 10.X.Y.2): DDS discovers across it with ``ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET``
and UDP only (``FASTDDS_BUILTIN_TRANSPORTS=UDPv4``: Fast DDS's shared memory would cross the
namespaces, which hosts do not share).  Both hosts see the same filesystem, as a cluster's
shared storage would be.  Creating namespaces needs root: elsewhere the tests skip and say so.
Every process is started in a session of its own and killed by session at the end; the
namespaces are deleted with their veth pair.
"""

from __future__ import annotations

import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from helpers import wait_until
from nav_sim.paths import executable_path
from nav_sim.ros.process import executable_command, ros_args

BIN = Path(sys.prefix) / 'bin'
DDS = {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET', 'FASTDDS_BUILTIN_TRANSPORTS': 'UDPv4',
       'ROS_DOMAIN_ID': '17', 'MUJOCO_GL': 'egl', 'AMENT_PREFIX_PATH': sys.prefix}
RAY_PORT = 6379  # each namespace has its own ports: the default cannot collide


def ip(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(['ip', *args], capture_output=True, text=True, timeout=30)


@dataclass
class Hosts:
    """Two network namespaces joined by a veth pair, and the processes started in them."""

    names: tuple[str, str]
    addresses: tuple[str, str]
    links: tuple[str, str]
    started: list[subprocess.Popen] = field(default_factory=list)

    def start(self, host: int, command: list[str], env: dict[str, str], log: Path
              ) -> subprocess.Popen:
        """Start ``command`` in namespace ``host`` (0 or 1), in a session of its own."""
        handle = open(log, 'w')  # noqa: SIM115 - the child writes to it until killed
        variables = [f'{k}={v}' for k, v in env.items()]
        process = subprocess.Popen(['ip', 'netns', 'exec', self.names[host], 'env',
                                    *variables, *command], stdout=handle,
                                   stderr=subprocess.STDOUT, start_new_session=True)
        handle.close()
        self.started.append(process)
        return process

    def run(self, host: int, command: list[str], env: dict[str, str], timeout: float
            ) -> subprocess.CompletedProcess:
        """Run ``command`` in namespace ``host`` to its end."""
        variables = [f'{k}={v}' for k, v in env.items()]
        return subprocess.run(['ip', 'netns', 'exec', self.names[host], 'env', *variables,
                               *command], capture_output=True, text=True, timeout=timeout)

    def link(self, host: int, up: bool) -> None:
        """Take ``host``'s end of the veth pair down or up again (with its multicast route)."""
        ip('-n', self.names[host], 'link', 'set', self.links[host], 'up' if up else 'down')
        if up:
            ip('-n', self.names[host], 'route', 'replace', '224.0.0.0/4', 'dev',
               self.links[host])

    def kill_all(self, grace: float = 5.0) -> None:
        """SIGTERM every session started here, then SIGKILL what is left of them."""
        sessions = {p.pid for p in self.started}
        for sig, wait in ((signal.SIGTERM, grace), (signal.SIGKILL, 0.0)):
            for pid in _session_members(sessions):
                try:
                    os.kill(pid, sig)
                except ProcessLookupError:
                    pass
            deadline = time.monotonic() + wait
            while _session_members(sessions) and time.monotonic() < deadline:
                time.sleep(0.2)
        for process in self.started:
            process.wait(timeout=10)


def _session_members(sessions: set[int]) -> list[int]:
    ps = subprocess.run(['ps', '-eo', 'pid=,sid='], capture_output=True, text=True).stdout
    rows = (line.split() for line in ps.splitlines() if line.strip())
    return [int(pid) for pid, sid in rows if int(sid) in sessions]


@pytest.fixture(scope='module')
def hosts() -> Iterator[Hosts]:
    """Create the two namespaces and their link; remove them (and their processes) after."""
    if os.geteuid() != 0:
        pytest.skip('two hosts are two network namespaces, and `ip netns add` needs root')
    if shutil.which('ip') is None:
        pytest.skip('two hosts need the `ip` command (iproute2) to make network namespaces')
    tag = f'vn{os.getpid() % 100_000}'
    subnet = f'10.{200 + os.getpid() % 50}.{os.getpid() % 250}'
    made = Hosts((f'{tag}a', f'{tag}b'), (f'{subnet}.1', f'{subnet}.2'), (f'{tag}x', f'{tag}y'))
    try:
        for name in made.names:
            result = ip('netns', 'add', name)
            if result.returncode != 0:
                pytest.skip(f'cannot create a network namespace here: {result.stderr.strip()}')
        setup = [('link', 'add', made.links[0], 'type', 'veth', 'peer', 'name', made.links[1])]
        for host in (0, 1):
            ns, link, address = made.names[host], made.links[host], made.addresses[host]
            setup += [('link', 'set', link, 'netns', ns),
                      ('-n', ns, 'addr', 'add', f'{address}/24', 'dev', link),
                      ('-n', ns, 'link', 'set', 'lo', 'up'), ('-n', ns, 'link', 'set', link, 'up'),
                      # DDS discovery is multicast: route it over the link
                      ('-n', ns, 'route', 'add', '224.0.0.0/4', 'dev', link)]
        for args in setup:
            result = ip(*args)
            assert result.returncode == 0, f'ip {" ".join(args)}: {result.stderr}'
        yield made
    finally:
        made.kill_all()
        for name in made.names:
            for pid in ip('netns', 'pids', name).stdout.split():  # nothing of ours may remain
                os.kill(int(pid), signal.SIGKILL)
            ip('netns', 'del', name)


def test_training_attaches_to_a_sim_on_the_other_host_and_not_without_the_link(hosts,
                                                                               tmp_path):
    sim = hosts.start(0, [*executable_command(), *ros_args('/two')], DDS, tmp_path / 'sim.log')
    wait_until(lambda: 'nav_sim ready' in (tmp_path / 'sim.log').read_text(), 60.0, 'the sim')
    train = [str(BIN / 'nav-gym-train'), '--sim', 'attach', '--namespace', '/two',
             '--total-timesteps', '300', '--buffer-size', '500', '--runs-dir', str(tmp_path),
             '--sim-timeout', '10']
    result = hosts.run(1, [*train, '--run-name', 'across'], DDS, timeout=600)
    assert result.returncode == 0, result.stdout[-2000:] + result.stderr[-2000:]
    assert (tmp_path / 'across' / 'final_model.zip').is_file()
    hosts.link(1, up=False)
    try:
        started = time.monotonic()
        result = hosts.run(1, [*train, '--run-name', 'cut'], DDS, timeout=120)
        assert result.returncode == 1, result.stdout + result.stderr
        assert "no nav_sim node found in namespace '/two'" in result.stderr
        assert time.monotonic() - started < 60.0
    finally:
        hosts.link(1, up=True)
    assert sim.poll() is None  # the sim never noticed


def test_the_policy_node_drives_a_realtime_sim_on_the_other_host(hosts, tmp_path):
    from nav_eval.recording.bags import read_bag
    from nav_sim.ros import messages as ros_msgs
    sim_params = {'mode': 'realtime', 'realtime_rate': 2.0, 'seed': 101}
    hosts.start(0, [*executable_command(), *ros_args('/drive', sim_params)], DDS,
                tmp_path / 'sim.log')
    hosts.start(1, [str(executable_path('nav_gym', 'policy')), '--ros-args', '-r',
                    '__ns:=/drive', '-p', 'policy:=servo', '-p', 'period:=0.256'], DDS,
                tmp_path / 'policy.log')
    bag = tmp_path / 'bag'
    record = hosts.run(0, [str(BIN / 'nav-eval-record'), str(bag), '--namespace', '/drive',
                           '--duration', '15'], DDS, timeout=120)
    assert record.returncode == 0, record.stdout + record.stderr
    messages = read_bag(bag)
    decisions = [m for _, m in messages.get('/drive/policy/decision', [])]
    assert decisions and any(m.position[0] >= 0 for m in decisions), \
        (tmp_path / 'policy.log').read_text()
    assert messages.get('/drive/cmd_vel'), 'no cmd_vel crossed the link'
    events = [ros_msgs.parse_event(m) for _, m in messages['/drive/episode_event']]
    moved = [e for e in events if e and (e['linear'], e['angular']) != (0.0, 0.0)]
    assert moved, 'the robot never moved'


def test_a_sweep_from_the_worker_host_runs_one_trial_on_each_node(hosts, tmp_path):
    token = os.urandom(32).hex()
    for home in ('home_a', 'home_b', 'home_c'):
        (tmp_path / home).mkdir()
    token_file = tmp_path / 'home_b' / 'token'
    token_file.write_text(token)
    head_address = f'{hosts.addresses[0]}:{RAY_PORT}'
    common = {**DDS, 'RAY_AUTH_MODE': 'token', 'RAY_USAGE_STATS_ENABLED': '0',
              'RAY_worker_niceness': '0'}
    # each host its own HOME (no shared ~/.ray/auth_token): the head takes the token from the
    # environment, the worker node from a file (RAY_AUTH_TOKEN_PATH), as the recipe says
    head_env = {**common, 'HOME': str(tmp_path / 'home_a'), 'RAY_AUTH_TOKEN': token}
    worker_env = {**common, 'HOME': str(token_file.parent),
                  'RAY_AUTH_TOKEN_PATH': str(token_file)}
    ray = str(BIN / 'ray')
    # Ray's sockets live under its temp dir, and a socket path has at most 107 bytes
    temp = Path(tempfile.mkdtemp(prefix='vray', dir='/tmp'))
    try:
        run_cluster(hosts, tmp_path, temp, ray, head_address, head_env, worker_env)
    finally:
        hosts.kill_all()
        shutil.rmtree(temp, ignore_errors=True)


def run_cluster(hosts: Hosts, tmp_path: Path, temp: Path, ray: str, head_address: str,
                head_env: dict[str, str], worker_env: dict[str, str]) -> None:
    """Start the head, refuse a sweep without the token, join the worker, sweep."""
    head = hosts.start(0, [ray, 'start', '--head', f'--node-ip-address={hosts.addresses[0]}',
                           f'--port={RAY_PORT}', '--num-cpus=1', '--include-dashboard=false',
                           f'--temp-dir={temp / "a"}', '--block'], head_env,
                       tmp_path / 'head.log')
    sweep = [str(BIN / 'visnav-sweep'), '--address', head_address, '--storage', str(tmp_path),
             '--seeds', '1,2', '--cpus-per-trial', '1', '--no-baselines', '--curve-seeds', '',
             '--total-timesteps', '200', '--set', 'learning_starts=100', '--set',
             'checkpoint_freq=100', '--set', 'buffer_size=500', '--set', 'max_episode_steps=12',
             '--train-seeds', '101-102', '--heldout-seeds', '201-202']
    wait_until(lambda: 'ray start --address' in (tmp_path / 'head.log').read_text()
             or head.poll() is not None, 120.0, 'the Ray head')
    assert head.poll() is None, (tmp_path / 'head.log').read_text()[-3000:]
    # without the token: one line that says what to set, within seconds
    started = time.monotonic()
    refused = hosts.run(1, [*sweep, '--name', 'refused'],
                        {**DDS, 'HOME': str(tmp_path / 'home_c')}, timeout=120)
    assert refused.returncode == 1
    assert refused.stderr.strip().splitlines() == [
        f'visnav-sweep: error: the Ray cluster at {head_address} refused this machine (token '
        "authentication; RAY_AUTH_MODE is not set): set RAY_AUTH_MODE=token and the head's "
        'token (`ray get-auth-token` on the head prints it) in RAY_AUTH_TOKEN, or in the file '
        'RAY_AUTH_TOKEN_PATH names (default ~/.ray/auth_token), here and on every node before '
        '`ray start`'], refused.stderr
    assert time.monotonic() - started < 15.0 and not (tmp_path / 'refused').exists()
    hosts.start(1, [ray, 'start', f'--address={head_address}',
                    f'--node-ip-address={hosts.addresses[1]}', '--num-cpus=1',
                    f'--temp-dir={temp / "b"}', '--block'], worker_env,
                tmp_path / 'worker.log')
    status = [ray, 'status', f'--address={head_address}']
    wait_until(lambda: hosts.run(1, status, worker_env, 60).stdout.count(' node_') >= 2, 120.0,
             'the worker node in the cluster')
    result = hosts.run(1, [*sweep, '--name', 'two'], worker_env, timeout=900)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    nodes = {}
    for seed in (1, 2):
        log = (tmp_path / 'two' / 'logs' / f'seed{seed}.log').read_text()
        nodes[seed] = re.findall(r'ROS_DOMAIN_ID=\d+, node (\S+)', log)
        assert (tmp_path / 'two' / 'trials' / f'seed{seed}' / 'eval' / 'results.json').is_file()
    assert sorted(n[-1] for n in nodes.values()) == sorted(hosts.addresses), nodes
    assert (tmp_path / 'two' / 'Sweep.md').is_file()
