"""The sweep report's figures, drawn with rliable's plotting (matplotlib, Agg, PNG).

PNGs are saved without the 'Software' stamp, so the same statistics give identical files.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from rliable import plot_utils  # noqa: E402

from nav_eval.analysis import stats  # noqa: E402
from nav_eval.seeds import seed_range  # noqa: E402
from nav_eval.sweeps.spec import LABEL_JOIN, SETTINGS_JOIN  # noqa: E402

PROFILE_TAUS = np.linspace(0.0, 1.0, 21)
LEGEND_WIDTH = 48  # characters a legend line may hold before a configuration's name wraps


def _legend(ax: Any, loc: str) -> None:
    """Draw the legend with each long configuration name wrapped at its underscores.

    A name of many ``--set`` settings is wider than the axes; unwrapped, its legend pushed the
    plot aside in the saved (tight) figure.
    """
    handles, labels = ax.get_legend_handles_labels()
    ax.legend(handles, [_wrapped(label) for label in labels], loc=loc, fontsize='small')


def _wrapped(label: str, width: int = LEGEND_WIDTH) -> str:
    """Wrap a configuration's name between its settings (``key=value``), never inside one.

    A sweep names a configuration by its settings joined with ``SETTINGS_JOIN``, a folder of
    runs with ``LABEL_JOIN``.
    """
    separator = LABEL_JOIN if LABEL_JOIN in label else SETTINGS_JOIN
    settings: list[str] = []
    for token in label.split(separator):  # by SETTINGS_JOIN: a setting begins after a value
        if separator == SETTINGS_JOIN and settings and '=' not in settings[-1]:
            settings[-1] += f'{SETTINGS_JOIN}{token}'
        else:
            settings.append(token)
    lines = [settings[0]]
    for setting in settings[1:]:
        if len(lines[-1]) + len(separator) + len(setting) > width:
            lines[-1] += separator.rstrip()
            lines.append(setting)
        else:
            lines[-1] += separator + setting
    return '\n'.join(lines)


def _save(fig: Any, folder: Path, name: str) -> str:
    folder.mkdir(parents=True, exist_ok=True)
    fig.savefig(folder / name, dpi=100, bbox_inches='tight', metadata={'Software': None})
    plt.close(fig)
    return name


def _intervals(folder: Path, estimates: dict[str, Any], metric: str, name: str) -> str:
    names = list(stats.AGGREGATES)
    points = {c: np.array([e[a]['point'] for a in names]) for c, e in estimates.items()}
    intervals = {c: np.array([[e[a]['low'] for a in names], [e[a]['high'] for a in names]])
                 for c, e in estimates.items()}
    fig, _ = plot_utils.plot_interval_estimates(
        points, intervals, metric_names=names, algorithms=list(estimates),
        xlabel=f'held-out {metric.replace("_", " ")}', subfigure_width=3.4,
        row_height=0.6, xlabel_y_coordinate=-0.1 - 0.6 / len(estimates))
    return _save(fig, folder, name)


def _profile(folder: Path, success: dict[str, np.ndarray]) -> str:
    profiles, cis = stats.performance_profile(success, PROFILE_TAUS)
    fig, ax = plt.subplots(figsize=(6, 4))
    plot_utils.plot_performance_profiles(
        profiles, PROFILE_TAUS, performance_profile_cis=cis, ax=ax,
        xlabel=r'held-out success rate ($\tau$)',
        ylabel=r'fraction of seeds with success > $\tau$')
    _legend(ax, 'lower left')
    return _save(fig, folder, 'performance_profile.png')


def _curve(folder: Path, curves: dict[str, Any]) -> str | None:
    shown = {c: v for c, v in curves.items() if len(v['steps']) >= 1}
    if not shown:
        return None
    for config, value in shown.items():
        points, intervals = stats.iqm_curve({config: value['scores']})
        value['iqm'], value['low'], value['high'] = (
            points[config].tolist(), intervals[config][0].tolist(),
            intervals[config][1].tolist())
    seeds = next(iter(shown.values()))['seeds']
    # rliable's curve takes one x axis for every configuration: use the first one's
    frames = np.array(next(iter(shown.values()))['steps']) / 1000
    same = {c: v for c, v in shown.items() if len(v['steps']) == len(frames)}
    fig, ax = plt.subplots(figsize=(6, 4))
    plot_utils.plot_sample_efficiency_curve(
        frames, {c: np.array(v['iqm']) for c, v in same.items()},
        {c: np.array([v['low'], v['high']]) for c, v in same.items()},
        algorithms=list(same), ax=ax, xlabel='training steps (thousands)',
        ylabel='IQM held-out success', labelsize='medium', ticklabelsize='medium')
    ax.set_ylim(-0.03, 1.03)
    ax.set_title(f'held-out scenarios {seed_range(seeds)} ({len(seeds)} per checkpoint)',
                 fontsize='medium')
    _legend(ax, 'lower right')
    return _save(fig, folder, 'sample_efficiency.png')


def _improvement(folder: Path, improvement: dict[str, Any]) -> str:
    points = {k: v['point'] for k, v in improvement.items()}
    intervals = {k: np.array([v['low'], v['high']]) for k, v in improvement.items()}
    fig = plot_utils.plot_probability_of_improvement(points, intervals,
                                                     pair_separator=stats.PAIR_SEPARATOR,
                                                     figsize=(5, 0.5 + 0.4 * len(points)))
    return _save(fig if hasattr(fig, 'savefig') else fig.figure, folder,
                 'probability_of_improvement.png')


def write_figures(folder: Path, data: dict[str, Any], success: dict[str, np.ndarray],
                  curves: dict[str, Any]) -> dict[str, str]:
    """Draw every figure the data allows; return {figure key: file name under ``folder``}."""
    out: dict[str, str] = {}
    for metric, key in (('success_rate', 'intervals'), ('collision_rate', 'intervals_collision')):
        if data['aggregates'].get(metric):
            out[key] = _intervals(folder, data['aggregates'][metric], metric,
                                  f'intervals_{metric}.png')
    if success:
        out['profile'] = _profile(folder, success)
    curve = _curve(folder, curves)
    if curve:
        out['curve'] = curve
    if data.get('improvement'):
        out['improvement'] = _improvement(folder, data['improvement'])
    return out
