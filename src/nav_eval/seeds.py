"""Evaluation seeds: the banks every command shares, and the one way to read and write seeds.

A seed names one scenario of a split (``nav_sim.core.scenarios``: layout, start and goal drawn from
``(split, seed)``).  The workshop evaluates on ten seeds of each split; a sweep evaluates its
final models on a hundred of each and every checkpoint on thirty held-out ones.
"""

from __future__ import annotations

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


def parse_seeds(text: str) -> tuple[int, ...]:
    """'101-110' or '101,105,107' (or a mix) -> a tuple of non-negative seeds."""
    seeds: list[int] = []
    try:
        for part in text.split(','):
            lo, _, hi = part.strip().partition('-')
            seeds += list(range(int(lo), int(hi) + 1)) if hi else [int(lo)]
            if hi and int(hi) < int(lo):
                raise EvaluationError(f'bad seed range {part.strip()!r} in {text!r}: the first '
                                      f"seed must not exceed the last, e.g. '{hi}-{lo}'")
    except ValueError:
        raise EvaluationError(f"bad seed list {text!r}: use e.g. '101-110' or '101,102'") from None
    if not seeds or min(seeds) < 0:
        raise EvaluationError(f'bad seed list {text!r}: need at least one seed, all >= 0')
    return tuple(seeds)


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
