"""The load and probe processes of benchmarks/estop_latency.py, each the source of a `python -c` process of
its own (so the load it makes is not the pressing process's): PROBE, the machine's own lateness (a process
that sleeps 10 ms at a time and notes how late it wakes; prints "worst_s wakes" on SIGTERM); POLLER, clients
polling GET /api/rig and /api/sweeps back to back (argv: url, token, clients); VIEWERS, live-stream viewers
of the running sweep, some never reading (argv: host, port, viewer token, viewers, stalled); SPIN, a busy
process."""

PROBE = """
import signal, sys, time
worst, n = 0.0, 0
signal.signal(signal.SIGTERM, lambda *_: (print(f"{worst:.4f} {n}", flush=True), sys.exit(0)))
while True:
    t = time.monotonic(); time.sleep(0.01); worst = max(worst, time.monotonic() - t - 0.01); n += 1
"""
POLLER = """
import sys, threading, httpx
url, token, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
def poll(k):
    with httpx.Client(base_url=url, headers={"Authorization": "Bearer " + token}, timeout=30) as c:
        while True:
            c.get("/api/rig" if k % 2 else "/api/sweeps?limit=5")
for k in range(n):
    threading.Thread(target=poll, args=(k,), daemon=True).start()
threading.Event().wait()
"""

VIEWERS = """
import asyncio, json, socket, sys
host, port, token, n, stalled = sys.argv[1], int(sys.argv[2]), sys.argv[3], int(sys.argv[4]), int(sys.argv[5])
state = {"rec": None, "events": 0, "streams": 0}

async def get_json(path):
    r, w = await asyncio.open_connection(host, port)
    w.write(f"GET {path} HTTP/1.1\\r\\nHost: x\\r\\nAuthorization: Bearer {token}\\r\\nConnection: close\\r\\n\\r\\n".encode())
    body = (await r.read()).split(b"\\r\\n\\r\\n", 1)[1]
    w.close()
    return json.loads(body)

async def watch():  # the running sweep's recording: what viewers follow
    while True:
        try:
            sweeps = await get_json("/api/sweeps?limit=1")
            state["rec"] = sweeps[0]["recording_id"] if sweeps and sweeps[0]["state"] == "running" else None
        except Exception:
            state["rec"] = None
        await asyncio.sleep(0.2)

async def viewer(k):
    done = None
    while True:
        rec = state["rec"]
        if rec is None or rec == done:
            await asyncio.sleep(0.1)
            continue
        sock = socket.socket()
        if k < stalled:  # a slow reader: a small window, and never a read
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.setblocking(False)
        try:
            await asyncio.get_running_loop().sock_connect(sock, (host, port))
            r, w = await asyncio.open_connection(sock=sock, limit=2**24)  # a first batch is ~100 kB a line
            w.write(f"GET /api/recordings/{rec}/live?access_token={token} HTTP/1.1\\r\\nHost: x\\r\\n\\r\\n".encode())
            state["streams"] += 1
            if k < stalled:
                while state["rec"] == rec:
                    await asyncio.sleep(0.2)
            else:
                while (line := await r.readline()):
                    if line.startswith(b"event: "):
                        state["events"] += 1
                    if line.startswith(b"event: end"):
                        break
            w.close()
        except OSError:
            await asyncio.sleep(0.2)
        done = rec

async def main():
    asyncio.get_running_loop().create_task(watch())
    await asyncio.gather(*(viewer(k) for k in range(n)))

asyncio.run(main())
"""
SPIN = "while True: pass"
