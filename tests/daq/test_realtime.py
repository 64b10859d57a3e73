"""daq.realtime: the calling thread (only it) gets the real-time policy where the system allows it."""
import os
import threading

from daq.realtime import HEARTBEAT_PRIORITY, make_realtime


def test_a_thread_becomes_real_time_and_the_others_do_not():
    seen = {}

    def body():
        seen["granted"] = make_realtime(HEARTBEAT_PRIORITY)
        seen["policy"] = os.sched_getscheduler(0)
        seen["priority"] = os.sched_getparam(0).sched_priority

    t = threading.Thread(target=body)
    t.start()
    t.join()
    assert os.sched_getscheduler(0) == os.SCHED_OTHER  # the test's own thread is untouched
    if os.geteuid() == 0:
        assert seen == {"granted": True, "policy": os.SCHED_FIFO, "priority": HEARTBEAT_PRIORITY}
    else:  # refused without CAP_SYS_NICE: said, and nothing changed
        assert seen == {"granted": False, "policy": os.SCHED_OTHER, "priority": 0}
