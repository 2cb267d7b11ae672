"""What happened in a closed-loop episode, from the graph's timestamps (pure: numpy only).

In real time nobody waits: the sim advances one control period per tick of its own timer with
the newest ``cmd_vel``, and the policy node decides on its own timer from the newest image.
The evaluation listens to both and records, for every message, the wall-clock time its
publisher sent it (DDS's source timestamp; one clock on one host):

* a :class:`Tick` per control period: the period's sim stamp (the stamp of its image and event)
  and when the sim published its event (right after the period's physics);
* a :class:`Decision` per decision: the stamp of the image it was made from and when the
  policy published it (its ``cmd_vel`` goes out just before).

From these, per period, the command the sim applied (:func:`commands_in_effect`: the newest
decision published before the tick, not before the episode's reset and not older than the
sim's ``cmd_vel_timeout``).  The sim's own report checks it: a period that did not end the
episode carries the body twist it drove with.  A decision published just before a tick can
reach the sim just after it; the twist then shows the decision before it, which is taken
instead (a race, counted); a twist neither explains is a mismatch (counted).  Two consecutive
decisions with the same action are told apart by the timestamps alone.

Per image (:func:`image_latencies`), the latency of the policy's answer to it:

* **wall**: image published -> the first decision made from it published (rendering the image
  excluded: it is published after rendering);
* **sim**: the sim time from the image's stamp to the start of the first control period a
  command decided from it acted in.  0 is what lockstep gives (a decision acts in the period
  right after its image); each whole control period more is a period the robot drove on an
  older decision.  An image no command acted on has no sim latency (it was skipped).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from nav_sim.core.events import EVENT_NONE

TWIST_TOLERANCE = 1e-6  # m/s, rad/s: the sim's wheel -> twist round trip


@dataclass(frozen=True)
class Tick:
    """One control period as the sim published it."""

    stamp_ns: int            # sim time: the stamp of the period's image and event
    published_ns: int        # wall clock: when the sim published the period's event
    event: dict[str, Any]    # nav_sim.ros.messages.parse_event of the event


@dataclass(frozen=True)
class Decision:
    """One decision as the policy node published it (``policy/decision``)."""

    image_stamp_ns: int | None   # the decided image's stamp (None: no image at all)
    published_ns: int            # wall clock: when the policy published it
    values: dict[str, float]     # DECISION_FIELDS -> value

    @property
    def action(self) -> int:
        """Return the action (-1: a stop, for want of a usable image)."""
        return int(self.values['action'])

    @property
    def twist(self) -> tuple[float, float]:
        """Return the cmd_vel it sent (linear m/s, angular rad/s)."""
        return float(self.values['linear']), float(self.values['angular'])

    @property
    def q_values(self) -> list[float] | None:
        """Return its Q-values, or None (a stop, or the servo)."""
        q = [self.values.get(k, math.nan) for k in ('q_left', 'q_forward', 'q_right')]
        return None if any(math.isnan(v) for v in q) else [round(float(v), 6) for v in q]


def _candidates(decisions: Sequence[Decision], tick: Tick, since_ns: int,
                timeout_ns: int) -> list[Decision]:
    """Return the decisions that may be in effect in ``tick``'s period, the newest first."""
    times = [d.published_ns for d in decisions]
    i = bisect.bisect_left(times, tick.published_ns)
    out = []
    for decision in reversed(decisions[max(0, i - 2):i]):
        if decision.published_ns <= since_ns or \
                tick.published_ns - decision.published_ns > timeout_ns:
            break
        out.append(decision)
    return out


def commands_in_effect(ticks: Sequence[Tick], decisions: Sequence[Decision], since_ns: int,
                       timeout_ns: int) -> tuple[list[Decision | None], int, int]:
    """Return the decision in effect in each of ``ticks``' periods (None: none, a standstill).

    ``ticks`` are an episode's periods after its reset frame, in order; ``decisions`` all
    decisions in publishing order; ``since_ns`` when the reset frame was published (the reset
    stops the motors); ``timeout_ns`` the sim's ``cmd_vel_timeout``.  Also returns how many
    races the sim's twist corrected and how many twists nothing explains.
    """
    out: list[Decision | None] = []
    races = mismatches = 0
    for tick in ticks:
        candidates = _candidates(decisions, tick, since_ns, timeout_ns)
        chosen = candidates[0] if candidates else None
        if _checkable(tick) and not _drove(tick, chosen):
            earlier = candidates[1] if len(candidates) > 1 else None
            if _drove(tick, earlier) or (earlier is None and _drove(tick, None)):
                chosen, races = earlier, races + 1
            else:
                mismatches += 1
        out.append(chosen)
    return out, races, mismatches


def _checkable(tick: Tick) -> bool:
    """Tell whether a period's reported twist is the command's (it did not end the episode)."""
    return not tick.event.get('done') and tick.event.get('event') in (EVENT_NONE, None)


def _drove(tick: Tick, decision: Decision | None) -> bool:
    """Tell whether the period's reported twist is that decision's command (or a standstill)."""
    expected = (0.0, 0.0) if decision is None else decision.twist
    got = (float(tick.event.get('linear', math.nan)), float(tick.event.get('angular', math.nan)))
    return all(abs(a - b) <= TWIST_TOLERANCE for a, b in zip(expected, got, strict=True))


@dataclass
class ImageLatencies:
    """The latencies of the policy's answers to an episode's images (seconds)."""

    sim: list[float] = field(default_factory=list)        # one per image a command acted on
    wall: list[float] = field(default_factory=list)
    inference: list[float] = field(default_factory=list)  # the first decision's own time
    skipped: int = 0                                      # images no command acted on


def image_latencies(first: Tick, ticks: Sequence[Tick], commands: Sequence[Decision | None],
                    decisions: Sequence[Decision], image_published_ns: dict[int, int],
                    ) -> ImageLatencies:
    """Return the latencies of the policy's answers to the images of ``image_published_ns``.

    ``first`` is the reset frame's tick, ``ticks`` and ``commands`` the episode's periods and
    their commands (:func:`commands_in_effect`), ``decisions`` every decision, in publishing
    order, and ``image_published_ns`` when each image that could be answered was published
    (the episode's last image cannot: nothing follows it).
    """
    starts = {tick.stamp_ns: before.stamp_ns
              for before, tick in zip([first, *ticks], ticks, strict=False)}
    acted: dict[int, int] = {}
    for tick, command in zip(ticks, commands, strict=True):
        # a stop (an image too old, or none) answers no image, whatever stamp it carries
        stamp = None if command is None or command.action < 0 else command.image_stamp_ns
        if stamp is not None and stamp in image_published_ns and stamp not in acted:
            acted[stamp] = starts[tick.stamp_ns]
    first_decision: dict[int, Decision] = {}
    for decision in decisions:
        if decision.action >= 0 and decision.image_stamp_ns in acted:
            first_decision.setdefault(decision.image_stamp_ns, decision)
    out = ImageLatencies(skipped=len(set(image_published_ns) - set(acted)))
    for stamp, start in sorted(acted.items()):
        decision = first_decision[stamp]
        out.sim.append((start - stamp) / 1e9)
        out.wall.append((decision.published_ns - image_published_ns[stamp]) / 1e9)
        out.inference.append(float(decision.values.get('inference_ms', math.nan)) / 1e3)
    return out


def quantiles_ms(seconds: Sequence[float]) -> dict[str, float]:
    """Return the median, p90, p99 and max of durations, in milliseconds."""
    ms = 1e3 * np.asarray(seconds, dtype=float)
    out = {name: round(float(np.quantile(ms, q)), 3)
           for name, q in (('median', 0.5), ('p90', 0.9), ('p99', 0.99))}
    out['max'] = round(float(ms.max()), 3)
    return out


def latency_summary(sim_s: Sequence[float], wall_s: Sequence[float], period_s: float,
                    inference_s: Sequence[float] = ()) -> dict[str, Any]:
    """Summarise decision latencies: wall-clock quantiles, sim time in whole control periods.

    ``periods`` maps "k periods late" (k = round(sim latency / period)) to its share of the
    decisions; k = 0 is what lockstep gives.  ``inference_s``: the policy's own time per
    decision (observation + network), summarised as ``inference_ms``.
    """
    out: dict[str, Any] = {'decisions': len(wall_s)}
    if not wall_s:
        return out
    out['wall_ms'] = quantiles_ms(wall_s)
    if len(inference_s):
        out['inference_ms'] = quantiles_ms(inference_s)
    late = np.rint(np.asarray(sim_s, dtype=float) / period_s).astype(int)
    counts = np.bincount(late)
    out['periods'] = {str(k): round(float(n) / len(late), 4) for k, n in enumerate(counts)
                      if n}
    out['sim_s'] = {'median': round(float(np.median(sim_s)), 4),
                    'mean': round(float(np.mean(sim_s)), 4), 'max': round(float(max(sim_s)), 4)}
    return out
