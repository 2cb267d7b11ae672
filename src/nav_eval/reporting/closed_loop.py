"""The closed-loop evaluation in the report: lockstep and real time side by side (no ROS).

Reads ``RUN/eval_closed_loop/results.json`` (:mod:`nav_eval.evaluation.closed_loop`): the
final model in lockstep (``dqn_<split>``) and driving a realtime sim through the policy node at
each rate (``rt<R>_<split>``), on the same seeds.  Three tables and the reading of them: success
per set with the change against lockstep and the seeds whose outcome changed; the decision
latency (wall clock image -> cmd_vel, and how many control periods late a decision acted); and
what the gap is made of.
"""

from __future__ import annotations

from typing import Any

from nav_eval.reporting.format import num, pct, table
from nav_sim.core.events import OUTCOME_SUCCESS

COMPARISON = ('Set', 'Rate', 'Episodes', 'Success', 'Δ success vs lockstep', 'Collision',
              'Timeout', 'Mean length', 'Mean SPL', 'Outcome changed (seeds)')
LATENCY = ('Set', 'Decision period (s)', 'Images answered', 'Wall median (ms)',
           'Wall p99 (ms)', 'Wall max (ms)', 'Inference median / p99 (ms)',
           'Sim: 0 periods late', '1 period', '2+ periods', 'Images skipped',
           'Periods stopped', 'Races / mismatches')


def _outcomes(entry: dict[str, Any]) -> dict[int, str]:
    return {int(e['seed']): str(e['outcome']) for e in entry.get('episodes', [])}


def pairs(sets: list[dict[str, Any]]) -> list[tuple[dict[str, Any], list[dict[str, Any]]]]:
    """Return (lockstep set, its closed-loop sets) per split, in the order of ``sets``."""
    out = []
    for lockstep in (s for s in sets if 'realtime_rate' not in s):
        loops = [s for s in sets if 'realtime_rate' in s and s.get('split') == lockstep['split']]
        out.append((lockstep, sorted(loops, key=lambda s: float(s['realtime_rate']))))
    return out


def comparison_rows(lockstep: dict[str, Any], loops: list[dict[str, Any]]) -> list[list[Any]]:
    """Return the comparison table's rows: lockstep first, then each rate."""
    base = lockstep['summary']
    before = _outcomes(lockstep)
    rows = []
    for entry in [lockstep, *loops]:
        s = entry['summary']
        rate = entry.get('realtime_rate')
        after = _outcomes(entry)
        changed = sum(1 for seed, outcome in after.items() if before.get(seed) != outcome)
        rows.append([entry.get('label') or entry['name'],
                     'lockstep' if rate is None else f'{float(rate):g}x', s['episodes'],
                     pct(s['success_rate']),
                     '–' if rate is None else
                     f"{100 * (s['success_rate'] - base['success_rate']):+.0f} pt",
                     pct(s['collision_rate']), pct(s['timeout_rate']), num(s['mean_length'], 1),
                     num(s['mean_spl'], 3), '–' if rate is None else changed])
    return rows


def latency_rows(loops: list[dict[str, Any]]) -> list[list[Any]]:
    """Return the latency table's rows, one per closed-loop set."""
    rows = []
    for entry in loops:
        lat = entry.get('latency', {})
        wall, periods = lat.get('wall_ms', {}), lat.get('periods', {})
        inference = lat.get('inference_ms', {})
        later = sum(float(v) for k, v in periods.items() if int(k) >= 2)
        steps = sum(int(e['length']) for e in entry.get('episodes', []))
        checks = entry.get('checks', {})
        rows.append([entry['name'], num(entry.get('decision_period_s'), 3),
                     lat.get('decisions', 0), num(wall.get('median'), 1), num(wall.get('p99'), 1),
                     num(wall.get('max'), 1),
                     f"{num(inference.get('median'), 1)} / {num(inference.get('p99'), 1)}",
                     pct(periods.get('0', 0.0)),
                     pct(periods.get('1', 0.0)), pct(later),
                     f"{lat.get('images_skipped', 0)} of "
                     f"{lat.get('images_skipped', 0) + lat.get('images_acted_on', 0)}",
                     f"{checks.get('stopped_periods', 0)} of {steps}",
                     f"{checks.get('races', 0)} / {checks.get('twist_mismatches', 0)}"])
    return rows


def closed_loop_latency_table(sets: list[dict[str, Any]]) -> str:
    """Return the latency table of the closed-loop sets as Markdown (for the command's output)."""
    loops = [s for s in sets if 'realtime_rate' in s]
    return '\n'.join(table(LATENCY, latency_rows(loops)))


def gap_notes(lockstep: dict[str, Any], loops: list[dict[str, Any]]) -> list[str]:
    """Say what running without lockstep costs this policy, set by set, from the numbers."""
    before = _outcomes(lockstep)
    notes = []
    for entry in loops:
        after = _outcomes(entry)
        succeeded = {s for s, o in before.items() if o == OUTCOME_SUCCESS}
        lost = sorted(s for s, o in after.items() if s in succeeded and o != OUTCOME_SUCCESS)
        won = sorted(s for s, o in after.items() if s not in succeeded and o == OUTCOME_SUCCESS)
        lat = entry.get('latency', {})
        periods = lat.get('periods', {})
        on_time = float(periods.get('0', 0.0))
        steps = sum(int(e['length']) for e in entry.get('episodes', [])) or 1
        stopped = entry.get('checks', {}).get('stopped_periods', 0) / steps
        skipped = lat.get('images_skipped', 0)
        notes.append(
            f"- **{float(entry['realtime_rate']):g}x real time** (decisions every "
            f"{num(entry.get('decision_period_s'), 3)} s): for {pct(on_time)} of the images, "
            'the command answering the image acted in the control period right after it, as in '
            f'lockstep; for {pct(1.0 - on_time)} one or more periods later (wall-clock latency '
            f"median {num(lat.get('wall_ms', {}).get('median'), 1)} ms, p99 "
            f"{num(lat.get('wall_ms', {}).get('p99'), 1)} ms against a period of "
            f"{num(1e3 * float(entry.get('decision_period_s') or 0.0), 0)} ms). "
            f'{skipped} images no command acted on, and the robot stood still in '
            f'{pct(stopped, 1)} of the periods (no command yet after a reset, or a command '
            f'older than the timeout). Success {len(lost)} seeds lost ({_seeds(lost)}), '
            f'{len(won)} gained ({_seeds(won)}) against lockstep.')
    notes += ['', 'The policy is deterministic and sees the same first image in both modes, so '
              'every difference in outcome comes from timing: a decision that acts a period late, '
              'or a period without a command, changes the images that follow, and the episode '
              'diverges from there.', '']
    return notes


def _seeds(seeds: list[int]) -> str:
    return ', '.join(str(s) for s in seeds[:10]) + (' ...' if len(seeds) > 10 else '') or 'none'


def section_closed_loop(results: dict[str, Any] | None, run_shown: str) -> list[str]:
    """Build the report's closed-loop subsection (lockstep against real time), or say how."""
    lines = ['### Closed loop in real time against lockstep', '']
    if not results:
        return lines + ['Not evaluated yet: `nav-eval-evaluate '
                        f'{run_shown} --closed-loop` runs the final model through the policy '
                        'node against a realtime sim at 1x and 4x real time on held-out seeds '
                        '201-250 (and in lockstep on the same seeds).', '']
    lines += ['The final model in lockstep (the env waits for every decision) and driving a '
              'realtime sim through the policy node (`ros2 run nav_gym policy`; nobody waits), '
              'on the same seeds. Latency: wall clock from the sim publishing an image to the '
              "policy publishing its command; sim time from the image's stamp to the start of "
              'the control period the command first acted in (0 = as in lockstep), measured on '
              'the first decision made from each image.', '']
    for lockstep, loops in pairs(list(results.get('sets', []))):
        lines += table(COMPARISON, comparison_rows(lockstep, loops))
        if loops:
            lines += table(LATENCY, latency_rows(loops))
            lines += gap_notes(lockstep, loops)
    return lines
