"""The live view's fan-out: one reader of the rig controller's samples per recording, shared by all its
viewers, each viewer with a bounded queue that drops for a slow reader.

Before this, every viewer's stream asked the controller itself ten times a second, through the web
server's thread pool: 200 viewers were 2000 requests a second to the real-time controller (its heartbeat
waited behind them), took the thread pool's 40 workers from every sync route, and encoded its own JSON.
Now a recording's feed reads the controller once per LIVE_POLL_S (on a thread of its own, whatever the
number of viewers), encodes each batch once as an SSE event, and hands the same bytes to every viewer.
A viewer that does not keep up loses its oldest batches past VIEWER_QUEUE_FRAMES and is told how many
samples it missed (a `missed` event; sample numbers are consecutive, so `first` of the next `samples`
event says where it resumes). Nothing is kept per viewer once it leaves; a feed ends with its last viewer,
and when no feed is left the memory the streams used is given back to the system (server/memory.py).
"""
from __future__ import annotations

import asyncio
import json
import threading
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import AsyncIterator, Callable

from .memory import release_freed_memory

#: seconds between two reads of a recording's samples from the rig controller (one read per recording,
#: however many viewers: 10 a second against the ~200 decimated samples a second the controller keeps)
LIVE_POLL_S = 0.1
#: batches a viewer's queue holds (5 s at LIVE_POLL_S); past that its oldest are dropped and counted
VIEWER_QUEUE_FRAMES = 50
#: batches a feed keeps for viewers who join later (10 s at LIVE_POLL_S: the dashboard plots the last 10 s)
FEED_HISTORY_FRAMES = 100
#: a quiet stream gets a comment line this often, s (proxies close streams that stay silent)
KEEPALIVE_S = 10.0
#: threads reading the controller for all feeds (each read is one short request on the IPC channel)
READER_THREADS = 2

KEEPALIVE = b": keep-alive\n\n"


@dataclass(frozen=True)
class Frame:
    """One batch of samples, numbered first..last (consecutive), as the SSE event every viewer gets."""
    first: int
    last: int
    data: bytes


def samples_frame(channels: list[str], points: list) -> Frame:
    """points: (seq, t_s, value per channel) from the controller -> one `samples` event."""
    cols = list(zip(*points))
    first, last = int(cols[0][0]), int(cols[0][-1])
    payload = {"first": first, "seq": last, "t": cols[1], **{c: cols[2 + j] for j, c in enumerate(channels)}}
    return Frame(first, last, f"event: samples\nid: {last}\ndata: {json.dumps(payload)}\n\n".encode())


def end_event(recording_id: str, status: str) -> bytes:
    return f"event: end\ndata: {json.dumps({'recording_id': recording_id, 'status': status})}\n\n".encode()


def missed_event(samples: int, resume_seq: int) -> bytes:
    return (f"event: missed\ndata: {json.dumps({'missed_samples': samples, 'resume_seq': resume_seq})}\n\n"
            .encode())


class Viewer:
    """One connected client: a bounded queue of shared frames, and what it lost."""

    def __init__(self, after: int):
        self.queue: deque[Frame] = deque()
        self.wake = asyncio.Event()
        self.seen = after  # the last sample number it was given (or asked to start after)
        self.fresh = after == 0  # a new viewer starts with whatever the feed holds: nothing counts as missed
        self.missed_samples = 0  # since it was last told
        self.dropped_frames = 0  # over its whole connection (for GET /api/live)

    def offer(self, frame: Frame) -> None:
        if frame.last <= self.seen:
            return
        if len(self.queue) >= VIEWER_QUEUE_FRAMES:  # a slow reader: its oldest batch goes, counted
            self.queue.popleft()
            self.dropped_frames += 1
        self.queue.append(frame)
        self.wake.set()

    def next_bytes(self) -> bytes | None:
        """The next event to send (a `missed` notice first when samples were skipped), or None."""
        if not self.queue:
            return None
        frame = self.queue[0]
        if self.fresh:
            self.fresh, self.seen = False, frame.first - 1
        if frame.first > self.seen + 1:  # samples between what it saw and this frame were dropped
            gap = frame.first - self.seen - 1
            self.missed_samples += gap
            self.seen = frame.first - 1
            return missed_event(gap, frame.first)
        self.queue.popleft()
        self.seen = frame.last
        return frame.data


@dataclass
class Feed:
    """The shared reader of one recording and its viewers."""
    recording_id: str
    viewers: set = field(default_factory=set)
    history: deque = field(default_factory=lambda: deque(maxlen=FEED_HISTORY_FRAMES))
    end: bytes | None = None
    task: asyncio.Task | None = None
    reads: int = 0


class LiveFeeds:
    """The service's feeds. read_live(recording_id, after) -> the controller's answer ({"active",
    "channels", "points", "done"}); read_status(recording_id) -> the recording's status for the `end`
    event. Both are blocking calls, run on READER_THREADS threads of the feeds' own, never in the
    server's thread pool. `stopping` (set on shutdown) ends every stream."""

    def __init__(self, read_live: Callable[[str, int], dict], read_status: Callable[[str], str],
                 stopping: threading.Event | None = None, poll_s: float = LIVE_POLL_S, batch_limit: int = 2000):
        """batch_limit: the most points one read returns (the controller's LIVE_BATCH)."""
        self.read_live, self.read_status, self.poll_s, self.batch_limit = read_live, read_status, poll_s, batch_limit
        self.stopping = stopping or threading.Event()
        self.feeds: dict[str, Feed] = {}
        self._readers = ThreadPoolExecutor(READER_THREADS, thread_name_prefix="live-reader")

    def close(self) -> None:
        self.stopping.set()
        for feed in list(self.feeds.values()):
            self._finish(feed, end_event(feed.recording_id, "running"))
        self._readers.shutdown(wait=False, cancel_futures=True)

    def stats(self) -> dict:
        """Per recording: viewers, the controller reads so far, the longest viewer queue, frames dropped."""
        return {rid: {"viewers": len(f.viewers), "controller_reads": f.reads,
                      "longest_queue_frames": max((len(v.queue) for v in f.viewers), default=0),
                      "dropped_frames": sum(v.dropped_frames for v in f.viewers)}
                for rid, f in self.feeds.items()}

    async def stream(self, recording_id: str, after: int = 0) -> AsyncIterator[bytes]:
        """The SSE byte stream of one viewer: recent samples after `after`, then new ones, then `end`."""
        feed = self.feeds.get(recording_id)
        if feed is None:
            feed = self.feeds[recording_id] = Feed(recording_id)
            feed.task = asyncio.get_running_loop().create_task(self._read(feed))
        viewer = Viewer(after)
        for frame in feed.history:
            viewer.offer(frame)
        feed.viewers.add(viewer)
        try:
            while True:
                data = viewer.next_bytes()
                if data is not None:
                    yield data
                elif feed.end is not None:
                    yield feed.end
                    return
                else:
                    viewer.wake.clear()
                    try:
                        await asyncio.wait_for(viewer.wake.wait(), KEEPALIVE_S)
                    except asyncio.TimeoutError:
                        yield KEEPALIVE
        finally:
            feed.viewers.discard(viewer)
            if not feed.viewers and self.feeds.get(recording_id) is feed:  # the last one out ends the feed
                del self.feeds[recording_id]
                if feed.task is not None and feed.end is None:
                    feed.task.cancel()
            if not feed.viewers and not self.feeds:  # the last viewer anywhere: its memory back (server/memory.py)
                release_freed_memory()

    async def _read(self, feed: Feed) -> None:
        """The feed's one reader: the controller's new samples every poll_s, to every viewer. A full
        batch means the controller holds more (a feed that starts late in a sweep): read on at once, and
        publish only the newest full batch, so viewers start with the last seconds, not the sweep's start."""
        loop = asyncio.get_running_loop()
        seq, behind = 0, None
        try:
            while feed.viewers:
                if self.stopping.is_set():
                    return self._finish(feed, end_event(feed.recording_id, "running"))
                try:
                    view = await loop.run_in_executor(self._readers, self.read_live, feed.recording_id, seq)
                except Exception:  # the controller unreachable or refusing: the stream ends, as before
                    view = {"active": False}
                feed.reads += 1
                points = view.get("points") or []
                if points:
                    frame = samples_frame(view["channels"], points)
                    seq = frame.last
                    if len(points) >= self.batch_limit and not view.get("done"):
                        behind = frame
                        continue
                    for ready in ((behind, frame) if behind is not None else (frame,)):
                        feed.history.append(ready)
                        for viewer in feed.viewers:
                            viewer.offer(ready)
                    behind = None
                elif not view.get("active") or view.get("done"):
                    status = await loop.run_in_executor(self._readers, self.read_status, feed.recording_id)
                    return self._finish(feed, end_event(feed.recording_id, status))
                await asyncio.sleep(self.poll_s)
        except asyncio.CancelledError:
            pass

    def _finish(self, feed: Feed, end: bytes) -> None:
        feed.end = end
        for viewer in feed.viewers:
            viewer.wake.set()
        if self.feeds.get(feed.recording_id) is feed:  # new viewers of this recording start a new feed
            del self.feeds[feed.recording_id]
