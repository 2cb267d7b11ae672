"""The policy node's settings (PolicyConfig) and their parameter types (no ROS)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from nav_sim.core.config import NON_NEGATIVE, check_bounds, setting
from nav_sim.errors import ConfigError

POLICIES = ('dqn', 'servo')


@dataclass(frozen=True)
class PolicyConfig:
    """Parameters of the policy node (``config/policy.yaml`` lists them with their defaults)."""

    model: str = setting('', "the trained model: a run directory (its final_model.zip), a "
                         "checkpoint .zip (its run's config.yaml gives the actions) or an "
                         "export directory (RUN/export: ONNX Runtime, no torch) ('' only with "
                         'policy servo)')
    policy: str = setting('dqn', "'dqn': the model's greedy action; 'servo': the image-only "
                          'servo baseline (turns toward green pixels; needs no model)')
    period: float = setting(0.0, 'decision period in wall-clock seconds (0: the control period '
                            "of the model's run, 0.512 s by default; at a sim's realtime_rate R "
                            'use ctrl_dt / R)', NON_NEGATIVE)
    image_timeout: float = setting(0.0, 'publish zero velocity while no image newer than this '
                                   '(wall-clock seconds) has arrived (0: two periods)',
                                   NON_NEGATIVE)
    device: str = setting('cpu', "torch device of the model: 'cpu' or 'cuda' (an ONNX export "
                          'runs on the CPU)')
    cmd_vel_stamped: bool = setting(False, 'publish cmd_vel as geometry_msgs/TwistStamped (what '
                                    "Jazzy's diff_drive_controller takes) instead of Twist")
    frame_id: str = setting('base_link', "with cmd_vel_stamped: the commands' header frame_id")
    cmd_vel_rate: float = setting(0.0, 'also publish the current command at this rate in Hz '
                                  'between decisions (0: once per decision); a controller that '
                                  'stops after cmd_vel_timeout needs a rate above 1/timeout',
                                  NON_NEGATIVE)

    def __post_init__(self) -> None:
        """Refuse values the node cannot run with (ConfigError)."""
        if self.policy not in POLICIES:
            raise ConfigError(f'policy must be one of {list(POLICIES)}, got {self.policy!r}')
        if self.policy == 'dqn' and not self.model:
            raise ConfigError('policy dqn needs a model: -p model:=RUN_DIR (or a .zip); or use '
                              '-p policy:=servo')
        check_bounds(self)


#: every policy node parameter and its declared type
PARAMETER_TYPES = {f.name: type(f.default) for f in dataclasses.fields(PolicyConfig)}
