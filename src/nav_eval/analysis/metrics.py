"""Task-level metrics of evaluation episodes (pure Python: no ROS, no MuJoCo, no torch).

SPL follows Anderson et al. 2018 / habitat-lab: ``SPL = S * l / max(p, l)`` with ``S`` success
(0/1), ``p`` the path length the robot drove and ``l`` the shortest-path distance.  visnav uses
the **straight-line start-to-goal-centre distance** for ``l``: a lower bound of the
obstacle-free shortest path (obstacles can only make it longer), so SPL here is never
overestimated by a bad planner.  Success triggers within ``goal_radius`` (10 cm) of the goal
centre, so a perfectly direct run scores ``p = l - 0.1 < l`` and SPL caps at 1.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, fields

from nav_sim.core.events import (
    EVENT_COLLISION,
    EVENT_GOAL,
    OUTCOME_COLLISION,
    OUTCOME_SUCCESS,
    OUTCOME_TIMEOUT,
)


@dataclass(frozen=True)
class EpisodeResult:
    """One evaluation episode."""

    seed: int
    split: str
    outcome: str
    length: int
    episode_return: float
    initial_distance: float
    final_distance: float
    path_length: float
    spl: float

    def to_dict(self) -> dict:
        """Return the episode as in results.json (``return``, floats rounded to 6 digits)."""
        out = asdict(self)
        out['return'] = out.pop('episode_return')
        return {k: (round(v, 6) if isinstance(v, float) else v) for k, v in out.items()}


@dataclass(frozen=True)
class SetSummary:
    """Aggregates of one evaluation set."""

    episodes: int
    success_rate: float
    collision_rate: float
    timeout_rate: float
    mean_length: float
    mean_spl: float
    mean_return: float

    def to_dict(self) -> dict:
        """Return the summary as in results.json (floats rounded to 6 digits)."""
        return {k: (round(v, 6) if isinstance(v, float) else v)
                for k, v in asdict(self).items()}


def spl(success: bool, shortest: float, path: float) -> float:
    """Success weighted by (normalised inverse) path length; 0 for a failure."""
    if not (math.isfinite(shortest) and math.isfinite(path)) or shortest < 0 or path < 0:
        raise ValueError(f'SPL needs finite, non-negative lengths (shortest={shortest}, '
                         f'path={path})')
    if not success:
        return 0.0
    if shortest == 0.0:
        return 1.0  # already at the goal: nothing to travel, habitat counts it as 1
    return shortest / max(path, shortest)


def outcome_of(event: str, truncated: bool) -> str:
    """'success' (goal), 'collision' or 'timeout' (time limit without a terminal event)."""
    if event == EVENT_GOAL:
        return OUTCOME_SUCCESS
    if event == EVENT_COLLISION:
        return OUTCOME_COLLISION
    if truncated:
        return OUTCOME_TIMEOUT
    raise ValueError(f'episode ended without goal, collision or time limit (event={event!r})')


def episode_result(seed: int, split: str, event: str, truncated: bool, length: int,
                   episode_return: float, initial_distance: float, final_distance: float,
                   path_length: float) -> EpisodeResult:
    """Build an EpisodeResult, computing outcome and SPL."""
    outcome = outcome_of(event, truncated)
    return EpisodeResult(seed, split, outcome, length, episode_return, initial_distance,
                         final_distance, path_length,
                         spl(outcome == OUTCOME_SUCCESS, initial_distance, path_length))


def summarize(episodes: Sequence[EpisodeResult]) -> SetSummary:
    """Rates and means of a set of episodes (raises on an empty set)."""
    n = len(episodes)
    if n == 0:
        raise ValueError('cannot summarise an empty evaluation set')

    def rate(outcome: str) -> float:
        return sum(e.outcome == outcome for e in episodes) / n

    return SetSummary(
        episodes=n, success_rate=rate(OUTCOME_SUCCESS), collision_rate=rate(OUTCOME_COLLISION),
        timeout_rate=rate(OUTCOME_TIMEOUT), mean_length=sum(e.length for e in episodes) / n,
        mean_spl=sum(e.spl for e in episodes) / n,
        mean_return=sum(e.episode_return for e in episodes) / n)


TABLE_COLUMNS = ('Set', 'Episodes', 'Success', 'Collision', 'Timeout', 'Mean length',
                 'Mean SPL', 'Mean return')


def summary_row(label: str, s: SetSummary) -> list[str]:
    """Return one row of :data:`TABLE_COLUMNS` for a set."""
    return [label, str(s.episodes), f'{s.success_rate:.0%}', f'{s.collision_rate:.0%}',
            f'{s.timeout_rate:.0%}', f'{s.mean_length:.1f}', f'{s.mean_spl:.3f}',
            f'{s.mean_return:.3f}']


def markdown_table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    """Return a GitHub-flavoured Markdown pipe table."""
    lines = ['| ' + ' | '.join(header) + ' |',
             '|' + '|'.join('---' if i == 0 else '---:' for i in range(len(header))) + '|']
    lines += ['| ' + ' | '.join(row) + ' |' for row in rows]
    return '\n'.join(lines)


def episodes_csv(sets: Iterable[tuple[str, Sequence[dict]]]) -> str:
    """Return all episodes as CSV, one row each, prefixed by the set name.

    The episodes are :meth:`EpisodeResult.to_dict` rows (as in results.json).
    """
    names = [('return' if f.name == 'episode_return' else f.name) for f in fields(EpisodeResult)]
    out = io.StringIO()
    writer = csv.writer(out, lineterminator='\n')
    writer.writerow(['set', *names])
    for set_name, episodes in sets:
        for row in episodes:
            writer.writerow([set_name, *[row[n] for n in names]])
    return out.getvalue()
