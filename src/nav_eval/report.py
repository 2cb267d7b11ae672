"""Write a run's result report (Markdown + self-contained HTML) with its figures.

    nav-eval-report RUN_DIR [--experiments docs/experiments.md]
    ros2 run nav_eval report RUN_DIR

Reads what the other commands left in RUN_DIR and writes RUN_DIR/report/Result.md, Result.html,
figures/*.png and the rollout videos videos/*.mp4 (:mod:`nav_eval.reporting.run_report`).
Every section is written; one whose input is missing says which command produces it.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from nav_eval.errors import ReportError
from nav_eval.reporting.run_report import write_report
from nav_gym.cli import run_command, strip_ros_args


def main(argv: list[str] | None = None) -> None:
    """Run the ``nav-eval-report`` command: write the report and print its paths."""
    parser = argparse.ArgumentParser(prog='nav-eval-report', description=__doc__.splitlines()[0])
    parser.add_argument('run_dir', type=Path, help='run directory made by nav-gym-train')
    parser.add_argument('--experiments', type=Path, metavar='FILE',
                        help='Markdown experiments log to include (e.g. docs/experiments.md)')
    args = parser.parse_args(strip_ros_args(argv))

    def body() -> int:
        try:
            report = write_report(args.run_dir, args.experiments)
        except OSError as exc:
            raise ReportError(f'cannot write the report: {exc}') from exc
        print(report)
        print(report.with_suffix('.html'))
        return 0

    run_command('nav-eval-report', body)


if __name__ == '__main__':
    main()
