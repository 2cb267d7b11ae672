"""The policy node's time budget: inference, throughput and decision latency, side by side.

    .venv/bin/python benchmarks/bench_policy.py [--run RUN] [--decisions 300] [--seconds 10]
                                                [--latency-seeds 201-203] [--rates 1,4]
                                                [--closed-loop-seeds 201-210]

1. **Inference** (in process, no ROS): one decision of the policy node (:class:`Controller`:
   the env's observation from a fresh 128x96 image, then the actor's one forward pass that
   gives the greedy action and the Q-values) against the evaluation's DQN policy acting on the
   same, ready observations (the same greedy step, :class:`nav_gym.policy.actors.DQNActor`,
   without the image conversion): median and p99 of each and their ratio.
2. **Throughput**: images per second the node turns into decisions, when a camera publishes as
   fast as it can and the node decides every millisecond (distinct image stamps decided on per
   second), against the same decisions in process.
3. **Decision latency** in the graph: the policy node driving a realtime sim at each rate,
   measured as the closed-loop evaluation measures it (wall clock: image published -> decision
   published; sim time: how many control periods late the answer acted).
4. **ONNX Runtime against PyTorch** (``nav-gym-export``): the node's decision in process with
   the exported network against the run's, interleaved on the same images, and the resident
   memory of a policy node process running each once it has decided (an export's process
   imports no torch).
5. With ``--run``: the closed-loop evaluation's table, lockstep against real time on the same
   seeds (``--closed-loop-seeds``), into a temporary folder.

Without ``--run`` the model is the default learner's untrained network (the same size, so the
same cost per decision).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)
os.environ.setdefault('MUJOCO_GL', 'egl')

import numpy as np  # noqa: E402

from nav_eval.analysis.closed_loop import ImageLatencies, latency_summary  # noqa: E402
from nav_eval.evaluation.closed_loop import (  # noqa: E402
    ClosedLoop,
    LoopSettings,
    evaluate_closed_loop,
    run_episode,
)
from nav_eval.evaluation.policies import DQNPolicy  # noqa: E402
from nav_eval.reporting.closed_loop import (  # noqa: E402  # noqa: E402
    COMPARISON,
    LATENCY,
    comparison_rows,
    latency_rows,
    pairs,
)
from nav_eval.reporting.format import table  # noqa: E402
from nav_eval.seeds import parse_seeds  # noqa: E402
from nav_gym.policy.actors import load_policy
from nav_gym.policy.config import PolicyConfig
from nav_gym.policy.controller import Controller  # noqa: E402
from nav_gym.training.config import TrainConfig  # noqa: E402
from nav_gym.training.run_dir import FINAL_MODEL, load_config  # noqa: E402
from nav_gym.training.timing import quiet_learner_threads  # noqa: E402
from nav_sim.core.kinematics import twist_to_wheels
from nav_sim.core.sim import NavSim  # noqa: E402
from nav_sim.ros import messages as ros_msgs  # noqa: E402


def untrained_run(folder: Path) -> Path:
    """Write a run directory with the default learner's untrained network; return it."""
    import gymnasium as gym

    from nav_gym.training.learner import learner_class, learner_kwargs, learner_policy
    from nav_gym.training.memory import stacked_space

    config = TrainConfig()
    (folder / 'config.yaml').write_text(config.to_yaml())
    learner = config.learner()

    class Spaces(gym.Env):  # the network's input: the default learner's stack
        observation_space = stacked_space(gym.spaces.Box(0, 255, (3, 84, 84), np.uint8),
                                          learner.frame_stack, 3 * learner.previous_action)
        action_space = gym.spaces.Discrete(3)

    model = learner_class(None, learner)(learner_policy(learner), Spaces(), buffer_size=10,
                                         device='cpu', **learner_kwargs(learner, config.gamma))
    model.save(folder / FINAL_MODEL)
    return folder


def rendered_images(count: int) -> list:
    """Return ``count`` camera images (sensor_msgs/Image, rgb8) of a turning robot."""
    sim = NavSim()
    try:
        sim.reset(101, 'train')
        images = []
        for _ in range(count):
            sim.step(twist_to_wheels(0.03, 0.75, sim.config))
            images.append(ros_msgs.image_msg(sim.render(), ros_msgs.stamp_from_ns(sim.sim_time_ns),
                                             'camera_optical_frame'))
        return images
    finally:
        sim.close()


def quantiles(seconds: list[float]) -> str:
    """Format the median and p99 of durations in milliseconds."""
    ms = 1e3 * np.asarray(seconds)
    return f'median {np.median(ms):7.2f} ms, p99 {np.quantile(ms, 0.99):7.2f} ms'


def inference(run: Path, images: list) -> tuple[list[float], list[float]]:
    """Per-decision seconds: the node's controller and the evaluation's DQN policy."""
    actor, acting = load_policy(PolicyConfig(model=str(run)))
    controller = Controller(actor, acting, image_timeout=1e9)
    evaluation = DQNPolicy(run / FINAL_MODEL)
    node, policy = [], []
    for image in images[:20]:  # warm-up
        controller.on_image(image)
        controller.decide()
    for image in images:
        controller.on_image(image)
        start = time.perf_counter()
        command = controller.decide()
        node.append(time.perf_counter() - start)
        start = time.perf_counter()
        evaluation.act(command.observation)
        policy.append(time.perf_counter() - start)
    return node, policy


def throughput(run: Path, images: list, seconds: float) -> float:
    """Distinct images per second the policy node process decided on (camera at full rate)."""
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import Image, JointState

    from nav_gym.policy.process import PolicyProcess
    from nav_sim import interface
    from nav_sim.ros import qos
    from nav_sim.ros.bare import own_node
    namespace = f'/bench_policy_{os.getpid()}'
    context, node = own_node('bench_camera', namespace)
    camera = node.create_publisher(Image, interface.IMAGE_TOPIC, qos.OBSERVATION)
    decided: dict[int, float] = {}
    node.create_subscription(JointState, interface.DECISION_TOPIC, lambda m: decided.setdefault(
        ros_msgs.stamp_to_ns(m.header.stamp), time.monotonic()), qos.DECISIONS)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    with PolicyProcess(namespace, {'model': str(run), 'period': 0.001}) as policy:
        try:
            deadline = time.monotonic() + 60.0
            while not decided and time.monotonic() < deadline:
                if policy.failure():
                    raise SystemExit(policy.failure())
                camera.publish(images[0])
                executor.spin_once(timeout_sec=0.05)
            decided.clear()
            stamp, start = 10**12, time.monotonic()
            while time.monotonic() - start < seconds:
                for image in images:
                    stamp += 1
                    image.header.stamp = ros_msgs.stamp_from_ns(stamp)
                    camera.publish(image)
                    executor.spin_once(timeout_sec=0.0)
                    if time.monotonic() - start >= seconds:
                        break
            end = time.monotonic()
            executor.spin_once(timeout_sec=0.2)
            return sum(1 for t in decided.values() if t <= end) / (end - start)
        finally:
            executor.shutdown(timeout_sec=1.0)
            node.destroy_node()
            context.try_shutdown()


def onnx_against_torch(run: Path, out: Path, images: list) -> tuple[list[float], list[float]]:
    """Per-decision seconds of the node's controller: the export's (ONNX, at ``out``), run's."""
    from nav_gym.policy.export import export_policy
    export = export_policy(run, out).path
    controllers = [Controller(*load_policy(PolicyConfig(model=str(model))), image_timeout=1e9)
                   for model in (export, run)]
    seconds: tuple[list[float], list[float]] = ([], [])
    for image in images[:20]:  # warm-up
        for controller in controllers:
            controller.on_image(image)
            controller.decide()
    for image in images:
        for controller, times in zip(controllers, seconds, strict=True):
            controller.on_image(image)
            start = time.perf_counter()
            controller.decide()
            times.append(time.perf_counter() - start)
    return seconds


def node_memory_mb(model: Path, image: object) -> float:
    """Resident memory (MB) of a policy node process on ``model`` once it has decided."""
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import Image, JointState

    from nav_gym.policy.process import PolicyProcess
    from nav_sim import interface
    from nav_sim.ros import qos
    from nav_sim.ros.bare import own_node
    namespace = f'/bench_policy_memory_{os.getpid()}'
    context, node = own_node('bench_camera', namespace)
    camera = node.create_publisher(Image, interface.IMAGE_TOPIC, qos.OBSERVATION)
    decided: list[float] = []
    node.create_subscription(JointState, interface.DECISION_TOPIC,
                             lambda m: decided.append(m.position[0]), qos.DECISIONS)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    with PolicyProcess(namespace, {'model': str(model), 'period': 0.05}) as policy:
        try:
            deadline = time.monotonic() + 60.0
            while time.monotonic() < deadline and not (decided and decided[-1] >= 0):
                if policy.failure():
                    raise SystemExit(policy.failure())
                camera.publish(image)
                executor.spin_once(timeout_sec=0.05)
            status = Path(f'/proc/{policy.process.pid}/status').read_text()
            return next(int(line.split()[1]) for line in status.splitlines()
                        if line.startswith('VmRSS:')) / 1024
        finally:
            executor.shutdown(timeout_sec=1.0)
            node.destroy_node()
            context.try_shutdown()


def latency(run: Path, rate: float, seeds: tuple[int, ...]) -> dict:
    """Return a closed-loop set's entry (latency, checks, lengths) of a few episodes."""
    config = load_config(run)
    loop = LoopSettings.of(config, rate)
    total, episodes, checks = ImageLatencies(), [], {}
    with ClosedLoop(config, {'model': str(run / FINAL_MODEL)}, loop) as closed:
        for seed in seeds:
            result, trace, _, got = run_episode(closed.graph, seed, 'heldout',
                                                config.env_config(), loop, [])
            total.sim += got.sim
            total.wall += got.wall
            total.inference += got.inference
            total.skipped += got.skipped
            episodes.append({'length': result.length})
            for key, value in trace['checks'].items():
                checks[key] = checks.get(key, 0) + value
    summary = latency_summary(total.sim, total.wall, loop.ctrl_dt, total.inference)
    return {'name': f'{rate:g}x', 'decision_period_s': loop.period, 'episodes': episodes,
            'checks': checks, 'latency': {**summary, 'images_acted_on': len(total.sim),
                                          'images_skipped': total.skipped}}


def main() -> None:
    """Measure and print the five parts."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--run', type=Path, help='a run directory (default: an untrained '
                        'network of the default learner; without it there is no part 4)')
    parser.add_argument('--decisions', type=int, default=300)
    parser.add_argument('--seconds', type=float, default=10.0)
    parser.add_argument('--latency-seeds', default='201-203')
    parser.add_argument('--rates', default='1,4')
    parser.add_argument('--closed-loop-seeds', default='201-210')
    args = parser.parse_args()
    quiet_learner_threads()
    rates = tuple(float(r) for r in args.rates.split(','))
    with tempfile.TemporaryDirectory() as folder:
        run = args.run or untrained_run(Path(folder))
        print(f'model: {run / FINAL_MODEL if args.run else "untrained default learner"}; '
              f'{os.cpu_count()} CPUs', flush=True)
        images = rendered_images(args.decisions)
        node, policy = inference(run, images)
        print(f'1. decision in process, {len(node)} fresh images (observation + network):')
        print(f'   policy node (one forward pass, argmax + Q):   {quantiles(node)}')
        print(f'   evaluation DQNPolicy (the same step, no image):  {quantiles(policy)}')
        print(f'   ratio node / evaluation (medians):             '
              f'{np.median(node) / np.median(policy):7.2f}', flush=True)
        rate = throughput(run, images, args.seconds)
        print(f'2. images turned into decisions, camera at full rate for {args.seconds:g} s:')
        print(f'   policy node process:  {rate:8.1f} images/s')
        print(f'   in process:           {1.0 / np.median(node):8.1f} decisions/s (median)')
        print(f'   ratio node / in process: {rate * np.median(node):6.2f}', flush=True)
        seeds = parse_seeds(args.latency_seeds)
        print(f'3. decision latency, policy node driving a realtime sim (held-out seeds '
              f'{args.latency_seeds}):')
        entries = [latency(run, r, seeds) for r in rates]
        print('\n'.join(f'   {line}' for line in table(LATENCY, latency_rows(entries))),
              flush=True)
        export = Path(folder) / 'export'
        onnx_s, torch_s = onnx_against_torch(run, export, images)
        print(f"4. ONNX Runtime against PyTorch, the node's decision in process "
              f'({len(onnx_s)} fresh images, interleaved):')
        print(f'   export (ONNX Runtime, 1 thread):  {quantiles(onnx_s)}')
        print(f'   run (PyTorch):                    {quantiles(torch_s)}')
        ratio = np.median(onnx_s) / np.median(torch_s)
        print(f'   ratio ONNX / PyTorch (medians):   {ratio:7.2f}')
        memory = {name: node_memory_mb(model, images[0])
                  for name, model in (('export', export), ('run', run))}
        print(f"   node process memory (RSS): export {memory['export']:.0f} MB, run "
              f"{memory['run']:.0f} MB, ratio {memory['export'] / memory['run']:.2f}",
              flush=True)
        if args.run:
            out = Path(folder) / 'closed_loop'
            results = evaluate_closed_loop(args.run, {'heldout': parse_seeds(
                args.closed_loop_seeds)}, rates, out, record=False)
            print(f'5. lockstep against real time, held-out seeds {args.closed_loop_seeds}:')
            for lockstep, loops in pairs(results['sets']):
                print('\n'.join(f'   {line}' for line in table(
                    COMPARISON, comparison_rows(lockstep, loops))))
                print('\n'.join(f'   {line}' for line in table(LATENCY, latency_rows(loops))))


if __name__ == '__main__':
    main()
