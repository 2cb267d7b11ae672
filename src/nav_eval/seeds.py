"""Evaluation seeds: the banks every command shares, and the one way to read and write seeds.

A seed names one scenario of a split (``nav_sim.core.scenarios``: layout, start and goal drawn from
``(split, seed)``).  The workshop evaluates on ten seeds of each split; a sweep evaluates its
final models on a hundred of each and every checkpoint on thirty held-out ones.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from nav_eval.errors import EvaluationError

#: the workshop's evaluation (``nav-eval-evaluate``, the main job): training and held-out seeds
WORKSHOP_TRAIN = tuple(range(101, 111))
WORKSHOP_HELDOUT = tuple(range(201, 211))
#: the closed-loop evaluation's default: held-out scenarios, in lockstep and in real time
CLOSED_LOOP_HELDOUT = tuple(range(201, 251))
#: a sweep's final evaluation (and the baselines): the training bank and the held-out bank
TRAIN_BANK = tuple(range(101, 201))
HELDOUT_BANK = tuple(range(201, 301))
#: held-out seeds a sweep evaluates every checkpoint on (the sample-efficiency curve)
CURVE = tuple(range(201, 231))


#: the most seeds one list may name: a longer one is refused before it is built (a typo)
MAX_SEEDS = 100_000
#: the most episodes an evaluation command runs without MANY_EPISODES_FLAG (the sweep's own
#: evaluations stay below it: 200 final episodes and 30 per checkpoint per trial)
MAX_EPISODES = 5_000
MANY_EPISODES_FLAG = '--many-episodes'
_MAX_SEED = 2**63 - 1  # a sim_node seed is a ROS integer parameter


def parse_seeds(text: str) -> tuple[int, ...]:
    """'101-110' or '101,105,107' (or a mix) -> a tuple of non-negative seeds.

    Each range is read as its bounds and checked (order, values, the total against
    :data:`MAX_SEEDS`) before any seed list is built.
    """
    parts: list[range] = []
    try:
        for part in text.split(','):
            lo, _, hi = part.strip().partition('-')
            first = int(lo)
            last = int(hi) if hi else first
            if last < first:
                raise EvaluationError(f'bad seed range {part.strip()!r} in {text!r}: the first '
                                      f"seed must not exceed the last, e.g. '{hi}-{lo}'")
            if first < 0 or last > _MAX_SEED:
                raise EvaluationError(f'bad seed list {text!r}: seeds are 0 to 2**63 - 1')
            parts.append(range(first, last + 1))
    except ValueError:
        raise EvaluationError(f"bad seed list {text!r}: use e.g. '101-110' or '101,102'") from None
    count = sum(len(part) for part in parts)
    if count > MAX_SEEDS:
        raise EvaluationError(f'seed list {text!r} names {count} seeds, more than the '
                              f'{MAX_SEEDS} one list may name')
    return tuple(seed for part in parts for seed in part)


def check_episodes(count: int, allowed: bool) -> None:
    """Refuse an evaluation of more than MAX_EPISODES episodes unless the flag allows it."""
    if count > MAX_EPISODES and not allowed:
        raise EvaluationError(f'{count} episodes is more than {MAX_EPISODES}: add '
                              f'{MANY_EPISODES_FLAG} to run them all')


def add_many_episodes_argument(parser: argparse.ArgumentParser) -> None:
    """Add the flag that allows an evaluation of more than MAX_EPISODES episodes."""
    parser.add_argument(MANY_EPISODES_FLAG, action='store_true',
                        help=f'allow more than {MAX_EPISODES} evaluation episodes')


def _contiguous(seeds: Sequence[int]) -> bool:
    return len(seeds) > 1 and list(seeds) == list(range(seeds[0], seeds[0] + len(seeds)))


def seed_text(seeds: Sequence[int]) -> str:
    """Write seeds as :func:`parse_seeds` reads them: '101-200' when contiguous, else '1,5'."""
    if _contiguous(seeds):
        return f'{seeds[0]}-{seeds[-1]}'
    return ','.join(str(s) for s in seeds)


def seed_range(seeds: Sequence[int]) -> str:
    """Show seeds in a report: '101–200' (an en dash) when contiguous, else '1,5'."""
    return seed_text(seeds).replace('-', '–') if _contiguous(seeds) else seed_text(seeds)
