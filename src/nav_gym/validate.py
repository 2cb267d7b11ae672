"""Print the workshop's environment validation checklist with measured values.

    nav-gym-validate [--namespace NS] [--sim auto|attach|embedded] [--json FILE]

Every line says PASS or FAIL; the command exits 1 if any check fails.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from nav_gym.cli import add_env_arguments, env_config, run_command, strip_ros_args
from nav_gym.env.checks import format_checklist, run_checklist, write_checklist
from nav_gym.env.navigation import NavigationEnv


def validate(args: argparse.Namespace) -> int:
    """Run the checklist on the env the options describe; return the exit code."""
    config = env_config(args)
    env = NavigationEnv(config)
    try:
        print(f'validating visnav/Navigation-v0 against nav_sim in {env.client.where}',
              flush=True)
        checks = run_checklist(env, lambda **kw: NavigationEnv(config, **kw))
    finally:
        env.close()
    print(format_checklist(checks))
    if args.json:
        write_checklist(checks, Path(args.json))
    return 0 if all(c.passed for c in checks) else 1


def main(argv: list[str] | None = None) -> None:
    """Run the ``nav-gym-validate`` command."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_env_arguments(parser)
    parser.add_argument('--json', help='also write the checklist as JSON to this file')
    args = parser.parse_args(strip_ros_args(argv))
    run_command('nav-gym-validate', lambda: validate(args))


if __name__ == '__main__':
    main()
