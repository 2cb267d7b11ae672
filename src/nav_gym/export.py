"""``nav-gym-export RUN``: the trained policy as ONNX for a robot without PyTorch.

    nav-gym-export RUN_OR_CHECKPOINT [--out DIR]

Writes ``RUN/export/policy.onnx`` and ``policy.json`` (:mod:`nav_gym.policy.exported`); the
policy node runs it with ``-p model:=RUN/export`` on ONNX Runtime.
"""

from __future__ import annotations

import argparse

from nav_gym.cli import run_command, strip_ros_args

PROG = 'nav-gym-export'


def main(argv: list[str] | None = None) -> None:
    """Run the ``nav-gym-export`` command (``ros2 run nav_gym export``)."""
    parser = argparse.ArgumentParser(prog=PROG, description=__doc__.splitlines()[0])
    parser.add_argument('model', metavar='RUN', help='a run directory (its final_model.zip) or '
                        'a checkpoint .zip')
    parser.add_argument('--out', help='the export directory (default: RUN/export)')
    args = parser.parse_args(strip_ros_args(argv))

    def body() -> int:
        from nav_gym.policy.export import export_policy  # torch: after the arguments
        spec = export_policy(args.model, args.out)
        print(f'{PROG}: wrote {spec.onnx} and {spec.path / "policy.json"}: run it with `ros2 '
              f'run nav_gym policy --ros-args -p model:={spec.path}`', flush=True)
        return 0

    run_command(PROG, body)


if __name__ == '__main__':
    main()
