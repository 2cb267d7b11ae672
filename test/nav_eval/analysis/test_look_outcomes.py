"""Held-out outcomes by drawn look, on constructed traces and summaries (no ROS)."""

from __future__ import annotations

import colorsys
import json

import pytest

from nav_eval.analysis import looks
from nav_eval.sweeps.collect import read_exported
from nav_eval.sweeps.report import _looks_markdown
from nav_eval.sweeps.statistics import look_rows, per_seed_rows
from nav_sim.core.config import HELDOUT
from nav_sim.core.looks import bands_of, draw_look


def hsv(hue_deg: float, saturation: float = 0.8, value: float = 0.8) -> list[float]:
    return list(colorsys.hsv_to_rgb(hue_deg / 360.0, saturation, value))


def trace(seed: int, outcome: str, obstacles: list[float] | None) -> tuple[None, dict]:
    scenario = {'seed': seed} if obstacles is None else {
        'seed': seed, 'look': {'floor': [0.5] * 3, 'walls': [0.5] * 3, 'obstacles': obstacles}}
    return None, {'seed': seed, 'outcome': outcome, 'scenario': scenario, 'steps': []}


def test_a_look_falls_in_its_hue_band_and_luminance_bin():
    bins = looks.look_bins({'obstacles': hsv(50.0)})  # yellow: the last band, 40-60 degrees
    assert bins[looks.HUE] == 'band 11 (40–60°)'
    assert bins[looks.LUMINANCE] == '≥ 0.45'
    assert looks.look_bins({'obstacles': hsv(190.0)})[looks.HUE] == 'band 00 (180–200°)'
    assert looks.look_bins({'obstacles': [0.3, 0.3, 0.3]})[looks.HUE] == 'grey'
    assert looks.look_bins({'obstacles': hsv(120.0)})[looks.HUE] == 'outside the drawn hues'
    assert looks.luminance([1.0, 1.0, 1.0]) == pytest.approx(1.0)
    edges = looks.LUMINANCE_EDGES
    assert [looks.luminance_label(v) for v in (0.0, edges[0], edges[1] - 1e-9, edges[2], 1.0)] \
        == ['< 0.25', '0.25–0.35', '0.25–0.35', '≥ 0.45', '≥ 0.45']


def test_held_out_looks_fall_only_in_the_held_out_bands():
    held_out = {looks.band_label(b) for b in bands_of(HELDOUT)}
    counts = looks.count_outcomes(trace(s, 'success', draw_look(s, HELDOUT).to_dict()['obstacles'])
                                  for s in range(201, 301))
    assert set(counts[looks.HUE]) <= held_out and len(counts[looks.HUE]) > 1
    assert sum(row[0] for row in counts[looks.HUE].values()) == 100
    assert sum(row[0] for row in counts[looks.LUMINANCE].values()) == 100


def test_outcomes_are_counted_per_bin_and_episodes_without_a_look_nowhere():
    episodes = [trace(1, 'success', hsv(50)), trace(2, 'collision', hsv(50)),
                trace(3, 'timeout', hsv(50, value=0.2)), trace(4, 'collision', None)]
    counts = looks.count_outcomes(episodes)
    yellow = looks.band_label(11)
    assert counts[looks.HUE] == {yellow: [3, 1, 1, 1]}
    assert counts[looks.LUMINANCE] == {'≥ 0.45': [2, 1, 1, 0], '< 0.25': [1, 0, 0, 1]}
    # bands by number (9 before 11), luminance from dark to bright
    mixed = looks.count_outcomes([trace(1, 'success', hsv(50)), trace(2, 'success', hsv(10)),
                                  trace(3, 'success', hsv(230, value=0.5))])
    assert [(r['factor'], r['bin']) for r in looks.rows(mixed)] == [
        (looks.HUE, 'band 02 (220–240°)'), (looks.HUE, 'band 09 (0–20°)'),
        (looks.HUE, yellow), (looks.LUMINANCE, '< 0.25'), (looks.LUMINANCE, '0.35–0.45'),
        (looks.LUMINANCE, '≥ 0.45')]
    assert looks.count_outcomes([trace(4, 'collision', None)]) == {}
    unreadable = trace(5, 'collision', hsv(50))
    del unreadable[1]['scenario']['look']['obstacles']
    assert looks.count_outcomes([unreadable]) == {}
    rows = looks.rows(looks.add([counts, counts]))
    assert [(r['factor'], r['bin'], r['episodes']) for r in rows] == [
        (looks.HUE, yellow, 6), (looks.LUMINANCE, '< 0.25', 2), (looks.LUMINANCE, '≥ 0.45', 4)]
    assert rows[0]['collision_rate'] == pytest.approx(1 / 3)
    assert rows[2]['timeout_rate'] == 0.0


def test_a_comparison_pools_a_runs_counts_with_those_its_summary_kept(tmp_path):
    final = {'heldout': {'summary': {'success_rate': 0.5, 'collision_rate': 0.5,
                                     'timeout_rate': 0.0, 'mean_spl': 0.4, 'episodes': 2}}}
    counts = looks.count_outcomes([trace(1, 'success', hsv(50)), trace(2, 'collision', hsv(50))])
    trial = {'seed': 1, 'steps': 50_000, 'wall_clock_s': 1.0, 'final': final, 'curve': {},
             'name': 'seed1', 'looks': counts}
    summary = tmp_path / 'summary'
    summary.mkdir()
    (summary / 'results.json').write_text(json.dumps(
        {'per_seed': per_seed_rows({'c': [trial]}), 'settings': {}}, sort_keys=True))
    exported = read_exported([summary])
    assert exported[0]['looks'] == counts  # through JSON, as a comparison reads it
    # a comparison's copy of the trial that kept no counts, read first: the later copy's count
    bare = tmp_path / 'a-bare'
    bare.mkdir()
    (bare / 'results.json').write_text(json.dumps(
        {'per_seed': per_seed_rows({'c': [{**trial, 'looks': {}}]}), 'settings': {}}))
    assert [t['looks'] for t in read_exported([bare, summary])] == [counts]
    run = {**trial, 'seed': 2, 'name': 'seed2'}
    plain = {**trial, 'seed': 3, 'name': 'seed3', 'looks': {}}  # trained and evaluated plain
    rows = look_rows({'c': [*exported, run, plain]})
    hue = [r for r in rows if r['factor'] == looks.HUE]
    assert [(r['seed'], r['episodes'], r['collision_rate']) for r in hue] == [('1, 2', 4, 0.5)]
    assert look_rows({'c': [plain]}) == []
    lines = '\n'.join(_looks_markdown(rows))
    assert '| c | 1, 2 | obstacle hue band | band 11 (40–60°) | 4 | 50% | 50% | 0% |' in lines
    assert 'No held-out trace carried a drawn look' in '\n'.join(_looks_markdown([]))
