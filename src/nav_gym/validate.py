"""Print the workshop's environment validation checklist with measured values.

    nav-gym-validate [--namespace NS] [--sim auto|attach|embedded] [--json FILE]

Every line says PASS or FAIL; the command exits 1 if any check fails.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict
from pathlib import Path

from nav_gym.checks import Check, run_checklist
from nav_gym.cli import add_env_arguments, env_config, run_command, strip_ros_args
from nav_gym.env import NavigationEnv


def format_checklist(checks: list[Check]) -> str:
    """Return the checklist as PASS/FAIL lines and a count."""
    width = max(len(c.name) for c in checks)
    lines = [f"{'PASS' if c.passed else 'FAIL'}  {c.name:<{width}}  {c.measured}"
             f"{'' if c.passed else f'  (expected: {c.expected})'}" for c in checks]
    failed = sum(not c.passed for c in checks)
    lines.append(f'{len(checks) - failed} passed, {failed} failed')
    return '\n'.join(lines)


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
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps([asdict(c) for c in checks], indent=2))
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
