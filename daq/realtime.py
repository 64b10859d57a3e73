"""Real-time scheduling for the few threads that keep a table safe (heartbeat, emergency stop).

On a busy machine the ordinary Linux scheduler can leave a thread that wakes up waiting for a whole
scheduling period: with sixty runnable threads (fifty dashboard pollers, say) that is ~200 ms, as long
as a watchdog. A thread under SCHED_FIFO runs as soon as it wakes. These threads sleep almost all the
time and do microseconds of work, so they cannot starve anything. Allowed for root or with
CAP_SYS_NICE; elsewhere the call does nothing and says so (the caller records it).

Why the whole rig controller and not only those threads: a real-time thread still needs Python's
interpreter lock, and if an ordinary thread of the same process holds it while the scheduler has put
it aside, the real-time thread waits for it (priority inversion: measured, heartbeats 250 ms late with
only the heartbeat thread real-time). So the controller runs under SCHED_RR at a low priority, and its
work is bounded by the rig's data rate (a 2048 Hz stream, a 20 Hz heartbeat), so it cannot hog a core.
"""
from __future__ import annotations

import os

#: priorities (1-99): the emergency stop above the heartbeat above the rest of the rig controller
CONTROLLER_PRIORITY = 10
HEARTBEAT_PRIORITY = 20
ESTOP_PRIORITY = 30


def make_realtime(priority: int, round_robin: bool = False) -> bool:
    """Put the calling thread under SCHED_FIFO (or SCHED_RR: time slices among equals) at `priority`;
    threads it starts later inherit it. True if the system allowed it."""
    try:
        policy = os.SCHED_RR if round_robin else os.SCHED_FIFO
        os.sched_setscheduler(0, policy, os.sched_param(priority))  # 0: the calling thread
        return True
    except (AttributeError, OSError):
        return False
