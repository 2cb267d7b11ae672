"""Report figures: training curves, top-down trajectories and camera contact sheets.

Pure matplotlib (``Agg`` backend) on the files a run directory holds; no ROS, no MuJoCo.  Every
figure function writes a PNG and returns its path.  Geometry follows ``nav_sim.core.scenarios``:
the arena is the square ``[-half_size, half_size]^2`` with the interior walls ``arena['walls']``
(axis-aligned boxes: centre x, y and half extents); obstacle slot ``i`` has the footprint
``arena['shapes'][i]`` (a box with half extents ``half_x``, ``half_y`` rotated by the placement's
yaw, or a cylinder of radius ``half_x``).  A scenario with a drawn look (``scenario['look']``,
``nav_sim.core.looks``) is drawn in its floor, wall and obstacle colours.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import matplotlib

from nav_sim.core.events import (
    EVENT_COLLISION,
    EVENT_NONE,
    OUTCOME_COLLISION,
    OUTCOME_SUCCESS,
    OUTCOME_TIMEOUT,
)

matplotlib.use('Agg')

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.patches import Circle, Polygon, Rectangle  # noqa: E402

from nav_gym.env.actions import action_label  # noqa: E402
from nav_gym.training.run_dir import MONITOR, checkpoints, read_monitor, truthy  # noqa: E402

DPI = 100
OUTCOME_COLOURS = {OUTCOME_SUCCESS: 'tab:green', OUTCOME_COLLISION: 'tab:red',
                   OUTCOME_TIMEOUT: 'tab:orange'}


def monitor_arrays(path: Path) -> dict[str, np.ndarray]:
    """Read the episodes of an SB3 Monitor CSV as arrays.

    ``r``, ``l``, ``t``, ``steps`` (cumulative ``l``) and, when logged, ``is_success`` (0/1) and
    ``event``; parsed by :func:`nav_gym.training.run_dir.read_monitor` (its columns of strings).
    """
    columns = read_monitor(path)
    data = {key: np.array([float(v) for v in columns.get(key, [])]) for key in ('r', 'l', 't')}
    data['steps'] = np.cumsum(data['l'])
    if 'is_success' in columns:
        data['is_success'] = np.array([float(truthy(v)) for v in columns['is_success']])
    if 'event' in columns:
        data['event'] = np.array(columns['event'], dtype=str)
    return data


def rolling_mean(values: np.ndarray, window: int) -> np.ndarray:
    """Trailing mean over ``window`` values (fewer at the start)."""
    values = np.asarray(values, dtype=float)
    sums = np.cumsum(np.insert(values, 0, 0.0))
    idx = np.arange(1, len(values) + 1)
    start = np.maximum(idx - window, 0)
    return (sums[idx] - sums[start]) / (idx - start)


def checkpoint_steps(run_dir: Path) -> list[int]:
    """Return the steps of the run's checkpoints, ascending."""
    return [steps for steps, _ in checkpoints(run_dir)]


def smoothing_window(episodes: int) -> int:
    """Return the rolling-mean window for a number of episodes (a tenth, 1 to 100)."""
    return max(1, min(100, episodes // 10))


def training_curves(run_dir: Path, out: Path) -> Path:
    """Episode return, length and (if logged) success/collision rate vs environment steps."""
    data = monitor_arrays(run_dir / MONITOR)
    rates = 'is_success' in data
    fig, axes = plt.subplots(3 if rates else 2, 1, figsize=(9, 8.4 if rates else 6),
                             sharex=True, dpi=DPI)
    steps, count = data['steps'], len(data['r'])
    window = smoothing_window(count)
    for ax, key, label in ((axes[0], 'r', 'episode return'), (axes[1], 'l', 'episode length')):
        ax.plot(steps, data[key], '.', ms=3, alpha=0.3, color='tab:blue', label='episode')
        ax.plot(steps, rolling_mean(data[key], window), color='tab:blue', lw=2,
                label=f'rolling mean ({window} episodes)')
        ax.set_ylabel(label)
    axes[1].set_ylabel('episode length (steps)')
    if rates:
        axes[2].plot(steps, 100 * rolling_mean(data['is_success'], window), color='tab:green',
                     lw=2, label='success')
        if 'event' in data:
            collided = (data['event'] == EVENT_COLLISION).astype(float)
            axes[2].plot(steps, 100 * rolling_mean(collided, window), color='tab:red', lw=2,
                         label='collision')
        axes[2].set_ylabel(f'rate over {window} episodes (%)')
        axes[2].set_ylim(-3, 103)
    for steps_at in checkpoint_steps(run_dir):
        for ax in axes:
            ax.axvline(steps_at, color='grey', ls='--', lw=1)
        axes[0].annotate(f'ckpt {steps_at:,}', (steps_at, 1), xycoords=('data', 'axes fraction'),
                         rotation=90, va='top', ha='right', fontsize=8, color='dimgrey')
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(loc='lower right', fontsize=8)
    if count == 0:
        axes[0].text(0.5, 0.5, 'no completed episodes yet', transform=axes[0].transAxes,
                     ha='center')
    axes[-1].set_xlabel('environment interactions (steps)')
    total = int(steps[-1]) if count else 0
    fig.suptitle(f'Training of {run_dir.name}: {count} episodes, {total:,} steps')
    return _save(fig, out)


def obstacle_patch(shape: dict[str, Any], placement: dict[str, Any], **style: Any
                   ) -> Circle | Polygon:
    """Return the footprint of one placed obstacle as a patch in arena coordinates."""
    x, y = float(placement['x']), float(placement['y'])
    if shape['kind'] == 'cylinder':
        return Circle((x, y), float(shape['half_x']), **style)
    return Polygon(box_corners(x, y, float(placement.get('yaw', 0.0)), float(shape['half_x']),
                               float(shape['half_y'])), closed=True, **style)


def box_corners(x: float, y: float, yaw: float, half_x: float, half_y: float) -> np.ndarray:
    """Corners (4, 2) of a box centred at (x, y) whose local x axis points along ``yaw``."""
    local = np.array([[half_x, half_y], [-half_x, half_y], [-half_x, -half_y], [half_x, -half_y]])
    c, s = math.cos(yaw), math.sin(yaw)
    return local @ np.array([[c, s], [-s, c]]) + np.array([x, y])


def draw_arena(ax: Axes, arena: dict[str, Any], scenario: dict[str, Any]) -> None:
    """Walls, obstacles, goal (marker and dashed success radius) and the start pose.

    In the scenario's drawn look if it has one, else in the plain colours.
    """
    look = scenario.get('look') or {}
    walls, floor, obstacles = (tuple(look[k]) if k in look else plain for k, plain in
                               (('walls', 'dimgrey'), ('floor', 'whitesmoke'),
                                ('obstacles', 'orangered')))
    half = float(arena.get('half_size', 1.0))
    wall = 0.05 * half
    ax.add_patch(Rectangle((-half - wall, -half - wall), 2 * (half + wall), 2 * (half + wall),
                           facecolor=walls, edgecolor='none', zorder=0))
    ax.add_patch(Rectangle((-half, -half), 2 * half, 2 * half, facecolor=floor,
                           edgecolor='black', lw=1, zorder=0.5))
    for x, y, half_x, half_y in arena.get('walls', []):
        ax.add_patch(Rectangle((x - half_x, y - half_y), 2 * half_x, 2 * half_y, facecolor=walls,
                               edgecolor='black', lw=0.5, zorder=0.8, gid='wall'))
    shapes = arena.get('shapes', [])
    for placement in scenario.get('obstacles', []):
        slot = int(placement['slot'])
        patch = obstacle_patch(shapes[slot], placement, facecolor=obstacles, alpha=0.8,
                               edgecolor='black' if look else 'darkred', zorder=1)
        patch.set_gid(f'obstacle_{slot}')
        ax.add_patch(patch)
    gx, gy = scenario['goal'][:2]
    ax.add_patch(Circle((gx, gy), float(arena.get('goal_marker_radius', 0.05)),
                        color='limegreen', zorder=2, gid='goal'))
    ax.add_patch(Circle((gx, gy), float(arena.get('goal_radius', 0.1)), fill=False,
                        ls='--', edgecolor='green', lw=1, zorder=2, gid='goal_radius'))
    sx, sy, syaw = scenario['start'][:3]
    length = 0.15 * half
    ax.arrow(sx, sy, length * math.cos(syaw), length * math.sin(syaw), width=0.012 * half,
             color='royalblue', zorder=4, length_includes_head=True, gid='start')
    ax.set_xlim(-half - wall, half + wall)
    ax.set_ylim(-half - wall, half + wall)
    ax.set_aspect('equal')


def draw_trajectory(ax: Axes, trace: dict[str, Any], arena: dict[str, Any],
                    compact: bool = False) -> Axes:
    """Draw one traced episode top-down: arena, path coloured by time, final pose, outcome."""
    scenario = trace['scenario']
    draw_arena(ax, arena, scenario)
    poses = np.array([scenario['start'][:3]] + [s['pose'][:3] for s in trace.get('steps', [])],
                     dtype=float)
    points = poses[:, :2].reshape(-1, 1, 2)
    if len(poses) > 1:
        path = LineCollection(np.concatenate([points[:-1], points[1:]], axis=1), cmap='viridis',
                              lw=2, zorder=3)
        path.set_array(np.arange(1, len(poses)))
        ax.add_collection(path)
        if not compact:
            ax.figure.colorbar(path, ax=ax, fraction=0.046, pad=0.04, label='step')
    outcome = trace.get('outcome', '?')
    colour = OUTCOME_COLOURS.get(outcome, 'black')
    fx, fy, fyaw = poses[-1]
    radius = float(arena.get('robot_radius', 0.037))
    ax.add_patch(Circle((fx, fy), radius, facecolor='none', edgecolor=colour, lw=2, zorder=5,
                        gid='final_pose'))
    ax.plot([fx, fx + 1.6 * radius * math.cos(fyaw)], [fy, fy + 1.6 * radius * math.sin(fyaw)],
            color=colour, lw=2, zorder=5)
    steps = len(poses) - 1
    if compact:
        ax.set_title(f"seed {trace.get('seed')}: {outcome} ({steps})", fontsize=9, color=colour)
        ax.set_xticks([])
        ax.set_yticks([])
    else:
        ax.set_title(f"{trace.get('set', '')} seed {trace.get('seed')} ({trace.get('split')}): "
                     f'{outcome} after {steps} steps', color=colour)
        ax.set_xlabel('x (m)')
        ax.set_ylabel('y (m)')
    return ax


def trajectory(trace: dict[str, Any], arena: dict[str, Any], out: Path,
               ax: Axes | None = None) -> Path:
    """Draw one episode top-down and save it.

    With ``ax`` the caller owns the figure: it is drawn into and saved, not closed.
    """
    if ax is not None:
        draw_trajectory(ax, trace, arena)
        out.parent.mkdir(parents=True, exist_ok=True)
        ax.figure.savefig(out, dpi=DPI, bbox_inches='tight')
        return out
    fig, ax = plt.subplots(figsize=(6.4, 5.6), dpi=DPI)
    draw_trajectory(ax, trace, arena)
    return _save(fig, out)


def trajectory_grid(traces: Sequence[dict[str, Any]], arena: dict[str, Any], out: Path,
                    title: str = '') -> Path:
    """Up to 10 episodes side by side (2 x 5), each titled with seed, outcome and length."""
    shown = list(traces)[:10]
    cols = min(5, max(1, len(shown)))
    rows = max(1, math.ceil(len(shown) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(2.6 * cols, 2.75 * rows), dpi=DPI,
                             squeeze=False)
    for ax in axes.flat[len(shown):]:
        ax.set_axis_off()
    for ax, trace in zip(axes.flat, shown, strict=False):
        draw_trajectory(ax, trace, arena, compact=True)
    if not shown:
        axes[0, 0].text(0.5, 0.5, 'no traces', ha='center', transform=axes[0, 0].transAxes)
    fig.suptitle(title or f'{len(shown)} episodes (path colour: early = dark, late = yellow)')
    return _save(fig, out)


def frame_indices(count: int, every: int | None = None, limit: int = 24) -> list[int]:
    """Which of ``count`` frames a contact sheet shows: evenly spaced, always the last one."""
    if count <= 0:
        return []
    every = every or max(1, math.ceil(count / limit))
    chosen = list(range(0, count, every))[:limit - 1]
    return chosen if chosen[-1] == count - 1 else [*chosen, count - 1]


def contact_sheet(frames: np.ndarray, out: Path, every: int | None = None,
                  labels: list[str] | None = None, title: str = '') -> Path:
    """Draw a grid of up to 24 camera frames ``(T, 3, H, W)`` uint8 with one label each."""
    frames = np.asarray(frames)
    if frames.ndim != 4:
        raise ValueError(f'expected frames of shape (T, 3, H, W), got {frames.shape}')
    if frames.shape[1] == 3:
        frames = frames.transpose(0, 2, 3, 1)
    chosen = frame_indices(len(frames), every)
    cols = min(6, max(1, len(chosen)))
    rows = max(1, math.ceil(len(chosen) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(1.7 * cols, 1.9 * rows + 0.4), dpi=DPI,
                             squeeze=False)
    for ax in axes.flat:
        ax.set_axis_off()
    for ax, index in zip(axes.flat, chosen, strict=False):
        ax.imshow(frames[index], interpolation='nearest')
        text = labels[index] if labels and index < len(labels) else f'step {index}'
        ax.set_title(text, fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    return _save(fig, out)


def frame_labels(steps: Sequence[dict[str, Any]]) -> list[str]:
    """'reset', then 'step N <action>' (plus the event, if any) for each traced step."""
    labels = ['reset']
    for number, step in enumerate(steps, start=1):
        name = str(step.get('action_name', step.get('action', '')))
        text = f"step {step.get('step', number)} {action_label(name)}"
        event = step.get('event', EVENT_NONE)
        labels.append(text if event in (EVENT_NONE, None) else f'{text} {event}')
    return labels


def _save(fig: Any, out: Path) -> Path:
    out.parent.mkdir(parents=True, exist_ok=True)
    try:
        fig.savefig(out, dpi=DPI, bbox_inches='tight')
    finally:
        plt.close(fig)
    return out
