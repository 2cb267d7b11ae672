"""The recorder's timestamp policy, without ROS: sim stamps, held messages, pauses, order."""

from __future__ import annotations

from nav_eval.recording.timestamps import NEVER, StampPolicy

S = 1_000_000_000


class Clock:
    """A wall clock that moves only when told to."""

    def __init__(self, now: int = 5 * S) -> None:
        self.now = now

    def __call__(self) -> int:
        return self.now


def test_stamped_messages_go_at_their_stamps_and_unstamped_at_the_sim_time_so_far():
    policy = StampPolicy(clock=Clock())
    assert policy.place('image', b'i1', 100) == [('image', 100, b'i1')]
    assert policy.place('cmd', b'c1', None) == [('cmd', 100, b'c1')]
    assert policy.place('image', b'i2', 200) == [('image', 200, b'i2')]
    assert policy.place('cmd', b'c2', None) == [('cmd', 200, b'c2')]
    assert policy.newest('image') == 200 and policy.newest('cmd') == -1


def test_unstamped_messages_before_any_sim_stamp_wait_for_the_first_one():
    policy = StampPolicy(clock=Clock())
    assert policy.place('cmd', b'c1', None) == []
    assert policy.place('note', b'n1', None) == []
    # the first stamped message releases them at its stamp, before itself
    assert policy.place('image', b'i1', 300) == [('cmd', 300, b'c1'), ('note', 300, b'n1'),
                                                  ('image', 300, b'i1')]
    assert policy.flush() == []


def test_without_a_sim_stamp_in_time_held_messages_go_at_their_arrival_times():
    clock = Clock()
    policy = StampPolicy(clock=clock, hold_s=10.0)
    assert policy.place('cmd', b'c1', None) == []
    clock.now += 4 * S
    assert policy.place('cmd', b'c2', None) == []
    clock.now += 7 * S  # 11 s after the first held one
    assert policy.place('cmd', b'c3', None) == [('cmd', 5 * S, b'c1'), ('cmd', 9 * S, b'c2'),
                                                ('cmd', 16 * S, b'c3')]
    assert policy.wall_clock
    clock.now += S  # later unstamped messages go at wall-clock time, even after a sim stamp
    policy.place('image', b'i1', 100)
    assert policy.place('cmd', b'c4', None) == [('cmd', 17 * S, b'c4')]


def test_too_many_held_messages_go_at_once():
    clock = Clock()
    policy = StampPolicy(clock=clock, hold_max=3)
    assert policy.place('cmd', b'1', None) == [] and policy.place('cmd', b'2', None) == []
    placed = policy.place('cmd', b'3', None)
    assert [data for _, _, data in placed] == [b'1', b'2', b'3'] and policy.wall_clock


def test_what_is_held_at_the_end_goes_at_its_arrival_time():
    clock = Clock()
    policy = StampPolicy(clock=clock)
    policy.place('cmd', b'c1', None)
    assert policy.flush() == [('cmd', 5 * S, b'c1')]
    assert policy.flush() == []


def test_timestamps_never_decrease_within_a_topic():
    policy = StampPolicy(clock=Clock())
    policy.place('image', b'i1', 500)
    # an older stamp on the same topic goes at the topic's last timestamp; another topic's
    # older stamp keeps its own
    assert policy.place('image', b'i0', 400) == [('image', 500, b'i0')]
    assert policy.place('odom', b'o0', 400) == [('odom', 400, b'o0')]
    assert policy.newest('image') == 500


def test_a_paused_recording_notes_stamps_but_writes_from_its_start():
    policy = StampPolicy(paused=True, clock=Clock())
    assert policy.start_ns == NEVER
    assert policy.place('image', b'warm-up', 100) == []
    assert policy.newest('image') == 100  # what wait_for sees
    assert policy.place('cmd', b'c0', None) == []
    policy.start(200)
    assert policy.place('image', b'old', 150) == []
    assert policy.place('cmd', b'c1', None) == []  # the sim time is still before the start
    assert policy.place('image', b'i2', 200) == [('image', 200, b'i2')]
    assert policy.place('cmd', b'c2', None) == [('cmd', 200, b'c2')]
