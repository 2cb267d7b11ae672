"""Training: the configuration, the learner, the run directory and the trainer (nav-gym-train).

``config`` (TrainConfig, LearnerSpec; no torch), ``learner`` (SB3 subclasses), ``run_dir``
(the one map of a run directory), ``files`` (atomic writes), ``checkpoints`` (checkpoints and
the replay buffer), ``timing`` (the env's share of the time), ``live_hooks`` (the training
statistics for the live view) and ``trainer`` (a run from start or resume to its summary: the
library that nav-gym-train, the pipeline and the sweep call).
"""
