"""Episode event names and outcome names: the one definition (no MuJoCo, no torch, no ROS).

The sim ends a control period early on a *terminal event* (``EVENT_GOAL`` or
``EVENT_COLLISION``) and reports ``EVENT_NONE`` otherwise; these strings travel on the
``episode_event`` topic, in ``info['event']``, in traces and in bags.  An evaluated episode's
*outcome* is ``OUTCOME_SUCCESS`` (the goal), ``OUTCOME_COLLISION`` or ``OUTCOME_TIMEOUT`` (the
time limit without a terminal event).  Reward, metrics and analysis import this module, which
stays light on purpose.
"""

from __future__ import annotations

EVENT_NONE = 'none'
EVENT_GOAL = 'goal'
EVENT_COLLISION = 'collision'
#: the events that end an episode (``terminated``)
TERMINAL_EVENTS = (EVENT_GOAL, EVENT_COLLISION)

OUTCOME_SUCCESS = 'success'
OUTCOME_COLLISION = 'collision'
OUTCOME_TIMEOUT = 'timeout'
#: every outcome, in the order reports list them
OUTCOMES = (OUTCOME_SUCCESS, OUTCOME_COLLISION, OUTCOME_TIMEOUT)
