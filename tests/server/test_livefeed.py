"""The live view's fan-out (server/livefeed.py): one reader per recording whatever the number of viewers,
a stalled viewer's queue bounded with its losses counted and told, nothing kept once viewers leave.

Driven by a source of numbered samples in the controller's answer format (the feed's input); waits are
on events (the source counts its reads), never on the clock.
"""
from __future__ import annotations

import asyncio
import json
import threading

from server.livefeed import VIEWER_QUEUE_FRAMES, LiveFeeds

POINTS_PER_READ = 20
CHANNELS = ["table_acc", "mass_acc"]


class Source:
    """The controller's live answers for one recording: POINTS_PER_READ new samples a read until `end`
    reads, then done. Counts the reads; `reached` is set at the read numbered `notify_at`."""

    def __init__(self, end: int, notify_at: int, hold: bool = False):
        """hold: the read after `notify_at` waits for `release` (viewers join while the feed is live)."""
        self.reads, self.end, self.notify_at = 0, end, notify_at
        self.reached, self.release = threading.Event(), threading.Event()
        if not hold:
            self.release.set()
        self.lock = threading.Lock()

    def read_live(self, recording_id: str, after: int) -> dict:
        if self.reads >= self.notify_at:
            self.release.wait()
        with self.lock:
            self.reads += 1
            if self.reads >= self.notify_at:
                self.reached.set()
            if self.reads > self.end:
                return {"active": True, "channels": CHANNELS, "points": [], "done": True}
            points = [(s, s / 200.0, 0.1 * s, -0.1 * s) for s in range(after + 1, after + 1 + POINTS_PER_READ)]
            return {"active": True, "channels": CHANNELS, "points": points, "done": False}

    def read_status(self, recording_id: str) -> str:
        return "complete"


def events(chunks: list[bytes]) -> list[tuple[str, dict]]:
    out = []
    for chunk in chunks:
        text = chunk.decode()
        if text.startswith(":"):
            continue
        name = next(line[7:] for line in text.splitlines() if line.startswith("event: "))
        data = next(line[6:] for line in text.splitlines() if line.startswith("data: "))
        out.append((name, json.loads(data)))
    return out


async def consume(stream, into: list) -> None:
    async for chunk in stream:
        into.append(chunk)


def test_viewers_share_one_reader_and_a_stalled_viewer_stays_bounded():
    async def scenario():
        n_viewers, reads = 25, VIEWER_QUEUE_FRAMES + 30
        source = Source(end=reads, notify_at=reads, hold=True)  # the end read waits: the feed is still there
        feeds = LiveFeeds(source.read_live, source.read_status, poll_s=0.0)
        stalled = feeds.stream("rec", 0)
        got_before_stall = [await stalled.__anext__()]  # connected, read one batch, then never again
        received = [[] for _ in range(n_viewers)]
        tasks = [asyncio.create_task(consume(feeds.stream("rec", 0), into)) for into in received]
        await asyncio.get_running_loop().run_in_executor(None, source.reached.wait)
        stats = feeds.stats()["rec"]
        assert stats["viewers"] == n_viewers + 1
        # the stalled viewer holds at most VIEWER_QUEUE_FRAMES batches; the rest were dropped and counted
        assert stats["longest_queue_frames"] == VIEWER_QUEUE_FRAMES
        assert stats["dropped_frames"] >= reads - 1 - VIEWER_QUEUE_FRAMES - 1
        source.release.set()
        await asyncio.gather(*tasks)  # the source ends: every fast viewer gets its `end`
        # one reader for all 26 viewers: the controller was asked once per batch (+1 for the end), not per viewer
        assert source.reads == reads + 1
        for chunks in received:
            evs = events(chunks)
            assert [name for name, _ in evs] == ["samples"] * reads + ["end"]
            seqs = [s for name, d in evs if name == "samples" for s in range(d["first"], d["seq"] + 1)]
            assert seqs == list(range(1, reads * POINTS_PER_READ + 1))  # every sample, in order, once
            assert evs[-1][1] == {"recording_id": "rec", "status": "complete"}
        # the stalled viewer resumes: told first how many samples it missed and where it resumes
        rest = [chunk async for chunk in stalled]
        evs = events(got_before_stall + rest)
        assert evs[0][0] == "samples" and evs[0][1]["seq"] == POINTS_PER_READ
        assert evs[1][0] == "missed"
        dropped = evs[1][1]["missed_samples"]
        assert dropped == (reads - 1 - VIEWER_QUEUE_FRAMES) * POINTS_PER_READ
        assert evs[1][1]["resume_seq"] == POINTS_PER_READ + dropped + 1 == evs[2][1]["first"]
        assert [name for name, _ in evs[2:]] == ["samples"] * VIEWER_QUEUE_FRAMES + ["end"]
        assert evs[-2][1]["seq"] == reads * POINTS_PER_READ
        # everyone gone: no feed, no viewer, no queue left behind
        assert feeds.feeds == {} and feeds.stats() == {}
        feeds.close()

    asyncio.run(scenario())


def test_the_last_viewer_leaving_stops_the_reader():
    async def scenario():
        source = Source(end=10**9, notify_at=3)
        feeds = LiveFeeds(source.read_live, source.read_status, poll_s=0.0)
        stream = feeds.stream("rec", 0)
        await stream.__anext__()
        await asyncio.get_running_loop().run_in_executor(None, source.reached.wait)
        task = next(iter(feeds.feeds.values())).task
        await stream.aclose()  # the client disconnected
        assert feeds.feeds == {}
        await asyncio.wait([task], timeout=30)
        assert task.done()  # the reader stopped with its last viewer
        feeds.close()

    asyncio.run(scenario())


def test_a_viewer_joining_late_gets_the_recent_batches_and_one_resuming_skips_what_it_saw():
    async def scenario():
        source = Source(end=6, notify_at=3, hold=True)
        feeds = LiveFeeds(source.read_live, source.read_status, poll_s=0.0)
        first, late, resumed = [], [], []
        tasks = [asyncio.create_task(consume(feeds.stream("rec", 0), first))]
        await asyncio.get_running_loop().run_in_executor(None, source.reached.wait)
        await asyncio.sleep(0)  # the third batch handed out
        tasks += [asyncio.create_task(consume(feeds.stream("rec", 0), late)),
                  asyncio.create_task(consume(feeds.stream("rec", 2 * POINTS_PER_READ), resumed))]
        await asyncio.sleep(0)
        assert feeds.stats()["rec"]["viewers"] == 3
        source.release.set()
        await asyncio.gather(*tasks)
        everything = list(range(1, 6 * POINTS_PER_READ + 1))
        for chunks, start in ((first, 1), (late, 1), (resumed, 2 * POINTS_PER_READ + 1)):
            evs = events(chunks)
            assert "missed" not in [n for n, _ in evs]
            seqs = [s for n, d in evs if n == "samples" for s in range(d["first"], d["seq"] + 1)]
            assert seqs == everything[start - 1:]
        assert source.reads == 7  # one reader for the three
        feeds.close()

    asyncio.run(scenario())
