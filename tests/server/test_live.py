"""The live view against a real `shakeid serve`: many viewers and a stalled one share one reader of the rig
controller, the emergency stop goes through while they are connected, every reader gets the end, and
nothing of them is kept once they leave (server/livefeed.py, server/routers/live.py).

Structure, not timing: the counts come from GET /api/live; waits are for states, never fixed sleeps.
"""
from __future__ import annotations
import pytest

import json
import socket
import threading

from .conftest import VIEWER, wait_for
pytestmark = pytest.mark.slow  # every test here (make check leaves them to make test)

VIEWERS = 30


def open_stream(port: int, rec_id: str, small_window: bool = False) -> socket.socket:
    sock = socket.socket()
    if small_window:  # a client that never reads: its window fills, the server's writes to it stall
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    sock.connect(("127.0.0.1", port))
    sock.sendall(f"GET /api/recordings/{rec_id}/live?access_token={VIEWER} HTTP/1.1\r\nHost: t\r\n\r\n".encode())
    return sock


def read_until_end(sock: socket.socket, into: dict, key: int) -> None:
    """Read the stream; `into[key]` gets the sample numbers seen and the end event's data."""
    sock.settimeout(120)
    buf, seqs = b"", []
    with sock:
        while b"event: end" not in buf:
            chunk = sock.recv(65536)
            if not chunk:
                break
            buf += chunk
    text = buf.decode(errors="replace")
    for block in text.split("\n\n"):
        if "event: samples" in block:
            data = json.loads(block.split("data: ", 1)[1].split("\n")[0])
            seqs.append((data["first"], data["seq"]))
    end = text.split("event: end\ndata: ", 1)[1].split("\n")[0] if "event: end" in text else None
    into[key] = {"seqs": seqs, "end": json.loads(end) if end else None}


def test_viewers_share_one_reader_and_the_estop_goes_through(service):
    with service.client() as op:
        wait_for(lambda: op.get("/api/rig").json()["active_sweep"] is None, what="an idle rig")
        op.post("/api/rig/reset")
        sweep = op.post("/api/sweeps", json={"f_start_hz": 1, "f_end_hz": 20, "duration_s": 600,
                                             "amplitude_mm": 1.0}).json()
        rec_id = wait_for(lambda: (s := op.get(f"/api/sweeps/{sweep['id']}").json())["state"] == "running"
                          and s["recording_id"], what="the sweep running")
        stalled = open_stream(service.port, rec_id, small_window=True)
        got: dict = {}
        readers = []
        for k in range(VIEWERS):
            sock = open_stream(service.port, rec_id)
            readers.append(threading.Thread(target=read_until_end, args=(sock, got, k)))
            readers[-1].start()
        feeds = wait_for(lambda: (f := op.get("/api/live").json()["recordings"]).get(rec_id, {}).get("viewers")
                         == VIEWERS + 1 and f, what="every viewer connected")
        assert list(feeds) == [rec_id]  # one feed (one reader of the controller) for 31 viewers
        stop = op.post("/api/rig/estop")
        assert stop.status_code == 200 and stop.json()["aborted_sweep"] == sweep["id"], stop.text
        for t in readers:
            t.join(120)
        assert len(got) == VIEWERS
        for seen in got.values():
            assert seen["end"] == {"recording_id": rec_id, "status": "aborted"}
            # numbered consecutively: each batch starts after the one before (no gap for a reader that keeps up)
            assert seen["seqs"] and all(b[0] == a[1] + 1 for a, b in zip(seen["seqs"], seen["seqs"][1:]))
        stalled.close()
        wait_for(lambda: op.get("/api/live").json()["recordings"] == {}, what="the feed gone with its viewers")
        op.post("/api/rig/reset")
