"""Rollout videos of evaluated episodes: the camera view beside a top-down view of the path.

Pure matplotlib (``Agg``) and imageio-ffmpeg on the files evaluation writes; no ROS, no MuJoCo.
One video frame per stored observation (the reset's, then one per step): on the left the
observation the policy received (``_frames.npz``: 84×84, the only camera frames evaluation
keeps; enlarged 4× by repeating pixels), on the right the arena (``plots.draw_arena``) with the
path so far and the robot; above them the episode (set, seed, split, outcome) and the step's
label (``plots.frame_labels``: step, action, event) with its reward, the return so far and the
distance to the goal.  Encoded as H.264 MP4 (``libx264``, ``yuv420p``, fast start) so browsers
play it in a ``<video>`` element.

The static parts are drawn once; each frame restores them and draws only the path, the robot
and the labels (matplotlib blitting): a 100-step episode takes about 1 s of Python and 0.6 s
of ffmpeg CPU time.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from nav_eval.reporting import plots
from nav_eval.reporting.run_inputs import Run, video_episodes
from nav_gym.training.run_dir import frames_path

FPS = 4  # one control period is 0.512 s: 4 frames/s is about twice real time
SIDE = 336  # pixels of each panel: the observation's and the top-down view's
MARGIN, HEADER = 16, 64
WIDTH, HEIGHT = 3 * MARGIN + 2 * SIDE, HEADER + 2 * MARGIN + SIDE  # 720×432: multiples of 16
# (H.264 macroblocks: imageio-ffmpeg would rescale other sizes)


def camera_scale(height: int, width: int) -> int:
    """Return the whole-pixel factor that fits an observation into the ``SIDE`` panel."""
    scale = SIDE // max(height, width)
    if scale < 1:
        raise ValueError(f'observations of {height}×{width} are larger than the video panel '
                         f'({SIDE}×{SIDE})')
    return scale


def video_name(trace: dict[str, Any]) -> str:
    """Name an episode's video file: ``<set>_seed_<seed>.mp4``."""
    return f"{trace.get('set', 'episode')}_seed_{trace.get('seed')}.mp4"


def frame_texts(trace: dict[str, Any]) -> list[str]:
    """Label each video frame: the step and action, its reward, return so far, distance."""
    steps = trace.get('steps', [])
    labels = plots.frame_labels(steps)
    distance = trace['scenario'].get('initial_distance')
    texts = [f'{labels[0]}: distance {distance:.2f} m' if distance is not None else labels[0]]
    total = 0.0
    for label, step in zip(labels[1:], steps, strict=True):
        total += float(step.get('reward', 0.0))
        texts.append(f"{label}: reward {float(step.get('reward', 0.0)):+.3f}, return "
                     f"{total:+.3f}, distance {float(step.get('distance', math.nan)):.2f} m")
    if steps:
        texts[-1] += f" | episode over: {trace.get('outcome', '?')}"
    return texts


def _channels_last(frames: np.ndarray) -> np.ndarray:
    frames = np.asarray(frames)
    if frames.ndim != 4 or 3 not in (frames.shape[1], frames.shape[3]):
        raise ValueError(f'expected frames of shape (T, 3, H, W), got {frames.shape}')
    return frames.transpose(0, 2, 3, 1) if frames.shape[1] == 3 else frames


class _Canvas:
    """The figure of one episode: static background drawn once, moving artists per frame."""

    def __init__(self, trace: dict[str, Any], arena: dict[str, Any], camera: tuple[int, int],
                 scale: int):
        import matplotlib.pyplot as plt
        from matplotlib.lines import Line2D
        from matplotlib.patches import Circle
        self.fig = plt.figure(figsize=(WIDTH / plots.DPI, HEIGHT / plots.DPI), dpi=plots.DPI)
        left = (2 * MARGIN + SIDE) / WIDTH
        ax = self.fig.add_axes((left, MARGIN / HEIGHT, SIDE / WIDTH, SIDE / HEIGHT))
        plots.draw_arena(ax, arena, trace['scenario'])
        ax.set_xticks([])
        ax.set_yticks([])
        outcome = trace.get('outcome', '?')
        self.fig.text(MARGIN / WIDTH, 1 - 10 / HEIGHT, f"{trace.get('set', '')} seed "
                      f"{trace.get('seed')} ({trace.get('split')}): {outcome} after "
                      f"{len(trace.get('steps', []))} steps", va='top', fontsize=12,
                      fontweight='bold', color=plots.OUTCOME_COLOURS.get(outcome, 'black'))
        self.fig.text(MARGIN / WIDTH, (MARGIN + SIDE + 4) / HEIGHT,
                      f'policy observation ({camera[1] // scale}×{camera[0] // scale})',
                      fontsize=8, color='dimgrey')
        self.fig.text(left, (MARGIN + SIDE + 4) / HEIGHT,
                      'top-down: path so far (blue), goal (green)', fontsize=8, color='dimgrey')
        self.label = self.fig.text(MARGIN / WIDTH, 1 - 36 / HEIGHT, '', va='top', fontsize=10,
                                   animated=True)
        radius = float(arena.get('robot_radius', 0.037))
        style = {'animated': True, 'zorder': 5}
        self.path = Line2D([], [], color='tab:blue', lw=2, **style)
        self.heading = Line2D([], [], color='black', lw=2, **style)
        self.robot = Circle((0, 0), radius, facecolor='white', edgecolor='black', lw=2, **style)
        for artist in (self.path, self.heading):
            ax.add_line(artist)
        ax.add_patch(self.robot)
        self.ax, self.radius = ax, radius
        self.fig.canvas.draw()
        self.background = self.fig.canvas.copy_from_bbox(self.fig.bbox)
        # where the observation goes, in buffer rows (top down) and columns
        top, left_px = HEADER + MARGIN + (SIDE - camera[0]) // 2, MARGIN + (SIDE - camera[1]) // 2
        self.rows = slice(top, top + camera[0])
        self.cols = slice(left_px, left_px + camera[1])

    def frame(self, image: np.ndarray, poses: np.ndarray, text: str,
              colour: str = 'black') -> np.ndarray:
        """Draw one RGB frame (HEIGHT, WIDTH, 3): the path up to ``poses[-1]``, the image."""
        canvas = self.fig.canvas
        canvas.restore_region(self.background)
        x, y, yaw = poses[-1]
        self.path.set_data(poses[:, 0], poses[:, 1])
        self.robot.center = (x, y)
        self.robot.set_edgecolor(colour)
        self.heading.set_data([x, x + 1.8 * self.radius * math.cos(yaw)],
                              [y, y + 1.8 * self.radius * math.sin(yaw)])
        self.heading.set_color(colour)
        self.label.set_text(text)
        for artist in (self.path, self.robot, self.heading):
            self.ax.draw_artist(artist)
        self.fig.draw_artist(self.label)
        rgb = np.asarray(canvas.buffer_rgba())[..., :3].copy()
        rgb[self.rows, self.cols] = image
        return rgb

    def close(self) -> None:
        import matplotlib.pyplot as plt
        plt.close(self.fig)


def episode_frames(trace: dict[str, Any], frames: np.ndarray,
                   arena: dict[str, Any]) -> Iterator[np.ndarray]:
    """Yield the video frames (HEIGHT, WIDTH, 3) uint8 of a traced episode's observations."""
    images = _channels_last(frames)
    steps = trace.get('steps', [])
    if len(images) != len(steps) + 1:
        raise ValueError(f'{len(images)} frames for {len(steps)} steps: expected one frame per '
                         'step plus the reset frame; re-run the evaluation')
    scale = camera_scale(*images.shape[1:3])
    poses = np.array([trace['scenario']['start'][:3]] + [s['pose'][:3] for s in steps],
                     dtype=float)
    texts = frame_texts(trace)
    outcome_colour = plots.OUTCOME_COLOURS.get(trace.get('outcome', ''), 'black')
    canvas = _Canvas(trace, arena, (images.shape[1] * scale, images.shape[2] * scale), scale)
    try:
        for index, image in enumerate(images):
            scaled = image.repeat(scale, axis=0).repeat(scale, axis=1)
            last = index == len(images) - 1
            yield canvas.frame(scaled, poses[:index + 1], texts[index],
                               outcome_colour if last and steps else 'black')
    finally:
        canvas.close()


def write_video(trace: dict[str, Any], frames: np.ndarray, arena: dict[str, Any], out: Path,
                fps: float = FPS) -> Path:
    """Encode one episode as H.264 MP4 at ``out`` (written atomically); returns ``out``."""
    import imageio_ffmpeg
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    partial = out.with_name(f'.{out.name}.partial.mp4')
    writer = imageio_ffmpeg.write_frames(
        str(partial), (WIDTH, HEIGHT), fps=fps, codec='libx264', quality=6,
        # veryfast: a third less encoder time than the default preset for 5 % larger files
        output_params=['-movflags', '+faststart', '-preset', 'veryfast'],
        ffmpeg_log_level='error')
    writer.send(None)  # start ffmpeg
    try:
        for rgb in episode_frames(trace, frames, arena):
            writer.send(np.ascontiguousarray(rgb))
    except BaseException:
        writer.close()
        partial.unlink(missing_ok=True)
        raise
    writer.close()
    partial.replace(out)
    return out


def write_trace_video(trace_path: Path, trace: dict[str, Any], arena: dict[str, Any],
                      folder: Path) -> Path | None:
    """Write the video of a trace written by evaluation into ``folder``.

    The frames are the trace's ``seed_<n>_frames.npz`` beside its ``seed_<n>.json``; returns
    None when they are missing.
    """
    frames_file = frames_path(trace_path)
    if not frames_file.is_file():
        return None
    with np.load(frames_file) as archive:
        frames = archive['obs']
    return write_video(trace, frames, arena, Path(folder) / video_name(trace))


#: the videos of a report: (caption, video path or None, why not) per episode, or what failed
Clips = Sequence[tuple[str, Path | None, str]] | str


def write_run_videos(run: Run, folder: Path) -> list[tuple[str, Path | None, str]]:
    """Write the video of every episode a run's report shows into ``folder``.

    The episodes are :func:`nav_eval.reporting.run_inputs.video_episodes`'.  Returns
    (caption, video path or None, why not) per episode; older videos in ``folder`` are removed.
    """
    arena = (run.results or {}).get('arena')
    episodes = video_episodes(run) if arena else []
    for stale in Path(folder).glob('*.mp4'):
        stale.unlink()
    written: list[tuple[str, Path | None, str]] = []
    for caption, path, trace in episodes:
        try:
            out = write_trace_video(path, trace, arena, folder)
        except (OSError, RuntimeError, ValueError, KeyError) as exc:
            written.append((caption, None, f'{type(exc).__name__}: {exc}'))
            continue
        written.append((caption, out, '' if out else f'no frames beside `{path.name}`'))
    return written
