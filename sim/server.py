"""The simulated rig on the wire: PLC over Modbus TCP (and ADS), accelerometers as a framed TCP stream.

    rig = SimulatedRig(PLCConfig(), speed=10.0).start()   # background thread, free loopback ports
    rig.endpoints   # {"modbus": ("127.0.0.1", p1), "stream": "socket://127.0.0.1:p2", ...}
    rig.stop()

One asyncio loop runs everything: every tick it advances the PLC by tick x speed of rig time (so
speed=10 runs the rig ten times faster, PLC clock and streams alike) and sends the new samples as
frames (protocol.frames) to every connected stream client. A stall of the process is not made up in one
jump (SimulatedRig.max_step_s): the rig's clock stops with it, as a real PLC's would not stall at all.
"""
from __future__ import annotations

import asyncio
import socket
import threading

import numpy as np

from protocol import can_frames, frames
from protocol.ads import AMS_PORT, default_net_id

from .modbus import make_server
from .plc import PLCConfig, RigPLC

#: ADC counts per m/s^2: +-32767 counts span +-50 m/s^2.
SENSITIVITY = 32767 / 50.0


#: Ports free_port draws from: below Linux's default ephemeral range (32768-60999), where the kernel
#: never puts the local end of an outgoing connection.
PORT_RANGE = (10000, 32767)
#: how long start() waits for the servers to listen, s: a hang guard (idle it takes well under a second; at
#: load 10 on 2 cores a CAN-remote rig's start took over 10 s, the bound it had)
START_TIMEOUT_S = 60.0


def _ephemeral_low() -> int:
    try:
        with open("/proc/sys/net/ipv4/ip_local_port_range") as f:
            return int(f.read().split()[0])
    except (OSError, ValueError, IndexError):
        return PORT_RANGE[1] + 1


def _bindable(host: str, port: int, reuse_address: bool = False) -> bool:
    """Whether a TCP socket can bind (host, port) now (with SO_REUSEADDR: a listener still blocks it)."""
    with socket.socket() as s:
        if reuse_address:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError:
            return False
        return True


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port nothing listens on now, for a server bound a moment later (SimulatedRig's Modbus and
    stream servers, started in their own thread; a test's service process).

    Drawn at random below the kernel's ephemeral range: a port the kernel hands out for port 0 is one it
    also gives to outgoing connections, and under a busy test run one of those took it between this
    check and the server's bind (a service failed to start with "address already in use"). Falls back
    to the kernel's choice when no port below the range is free."""
    top = min(PORT_RANGE[1], _ephemeral_low() - 1)
    if top > PORT_RANGE[0]:
        for port in np.random.default_rng().integers(PORT_RANGE[0], top + 1, size=200):
            if _bindable(host, int(port)):
                return int(port)
    with socket.socket() as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def free_ads_address() -> str:
    """A loopback address 127.a.b.c (Linux answers on all of 127/8) where nothing listens on the ADS
    port, for a SimulatedRig's ADS server (its `ads_address`). Drawn at random: with one fixed address,
    two test runs on one machine (a CI clone beside a developer's `make test`) both took 127.0.0.5, and
    the later one's rigs failed to start with "address already in use". ADS_PORT: the TCP port every ADS
    client dials and pyads' test server listens on (48898), so ADS servers on one machine differ by
    address only (imported here, not with the module: pyads takes ~40 ms to import)."""
    from pyads.testserver.testserver import ADS_PORT
    for a, b, c in np.random.default_rng().integers(1, 255, size=(200, 3)):
        host = f"127.{a}.{b}.{c}"
        if _bindable(host, ADS_PORT, reuse_address=True):  # as AdsTestServer binds
            return host
    raise RuntimeError(f"no loopback address with TCP {ADS_PORT} free (200 tried)")


class SimulatedRig:
    """speed: rig seconds per wall second; tick_s: wall time between physics steps;
    frame_samples: samples per channel in one stream frame."""

    def __init__(self, config: PLCConfig | None = None, host: str = "127.0.0.1", modbus_port: int = 0,
                 stream_port: int = 0, speed: float = 1.0, tick_s: float = 0.01, frame_samples: int = 64,
                 sensitivity: float = SENSITIVITY, ads_address: str | None = None,
                 can_interface: str | None = None, can_channel: str | None = None, can_node: int = 0,
                 stream_host: str | None = None, redundant_sensors: bool = False):
        self.plc = RigPLC(config)
        # a second accelerometer beside each of the two (own noise): 4 stream channels, as on rigs that
        # carry redundant sensors; the CAN frames keep the first two
        self.redundant_sensors = redundant_sensors
        self._rng = np.random.default_rng(1)
        self.stream_host = stream_host or host
        # CAN output (python-can): e.g. interface "virtual" (in-process) or "remote" (python-can-remote)
        self.can_interface, self.can_channel, self.can_node = can_interface, can_channel, can_node
        self.can_bus = None
        self._can_counter = 0
        self.ads_address = ads_address  # loopback address for the ADS server (it always listens on 48898)
        self.ads = None
        self.host = host
        self.modbus_port = modbus_port or free_port(host)
        self.stream_port = stream_port or free_port(stream_host or host)
        self.speed = speed
        self.tick_s = tick_s
        self.lost_rig_s = 0.0  # rig time not simulated because this process stalled (max_step_s)
        self.frame_samples = frame_samples
        self.sensitivity = sensitivity
        # drop_plc_link: Modbus requests fail; cut_plc_link_s: the PLC's TCP server goes away for that
        # long (rig time), connections drop and new ones are refused; drop_frames / corrupt_frames: the
        # next N stream frames; drop_can_frames: the next N CAN frames (samples);
        # stuck: the sensors repeat one value; saturate: the mass sensor reads beyond full scale;
        # disconnect_s: the stream drops its clients and refuses new ones for that long (rig time)
        self.fault_injection = {"drop_plc_link": False, "cut_plc_link_s": 0.0, "drop_frames": 0,
                                "corrupt_frames": 0, "drop_can_frames": 0, "stuck": False, "saturate": False, "disconnect_s": 0.0}
        self._modbus = None
        self._plc_cut_until: float | None = None
        self._disconnected_until = -1.0
        self._stuck_value = None
        self._clients: set[asyncio.StreamWriter] = set()
        self._pending = np.empty((0, 2))
        self._pending_first = 0
        self._seq = 0
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._stopping: asyncio.Event | None = None
        self.error: BaseException | None = None

    @property
    def endpoints(self) -> dict:
        return {"modbus": (self.host, self.modbus_port), "stream": f"socket://{self.stream_host}:{self.stream_port}",
                "ads": (default_net_id(self.ads_address), AMS_PORT, self.ads_address) if self.ads_address else None,
                "fs_hz": self.plc.config.fs_hz, "sensitivity_counts_per_ms2": self.sensitivity,
                "channels": ["table_acc", "mass_acc"] + (["table_acc_2", "mass_acc_2"] if self.redundant_sensors else [])}

    # -- lifecycle ------------------------------------------------------------------------------------
    def start(self, timeout: float = START_TIMEOUT_S) -> "SimulatedRig":
        self._thread = threading.Thread(target=self._run, name="simulated-rig", daemon=True)
        self._thread.start()
        if not self._ready.wait(timeout):
            raise RuntimeError(f"simulated rig did not start: its servers did not listen within {timeout:g} s")
        if self.error is not None:
            raise RuntimeError(f"simulated rig did not start: {self.error}")
        return self

    def stop(self, timeout: float = 10.0) -> None:
        """Stop the rig; safe to call more than once."""
        if self._thread is None or not self._thread.is_alive():
            return
        if self._loop is not None and self._stopping is not None and not self._loop.is_closed():
            self._loop.call_soon_threadsafe(self._stopping.set)
        if self._thread is not None:
            self._thread.join(timeout)

    def call(self, fn, *args):
        """Run fn(*args) on the rig's loop thread (the PLC is not thread-safe) and return its result."""
        fut = asyncio.run_coroutine_threadsafe(self._call(fn, *args), self._loop)
        return fut.result(5.0)

    async def _call(self, fn, *args):
        return fn(*args)

    def _run(self) -> None:
        try:
            asyncio.run(self._main())
        except BaseException as exc:  # reported to start()/the caller
            self.error = exc
            self._ready.set()

    async def _main(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stopping = asyncio.Event()
        await self._open_modbus()
        try:
            stream = await asyncio.start_server(self._on_stream_client, self.stream_host, self.stream_port)
        except OSError as exc:
            await self._modbus.shutdown()
            raise RuntimeError(f"the accelerometer stream cannot listen on {self.stream_host}:{self.stream_port}: "
                               f"{exc.strerror or exc}") from None
        if self.can_interface:
            import can

            self.can_bus = can.Bus(interface=self.can_interface, channel=self.can_channel)
        if self.ads_address:
            from .ads import AdsFrontEnd

            self.ads = AdsFrontEnd(self.plc, self.ads_address)
            self.ads.start()
        physics = asyncio.create_task(self._physics())
        await asyncio.sleep(0.05)
        self._ready.set()
        await self._stopping.wait()
        physics.cancel()
        stream.close()
        for w in list(self._clients):
            w.close()
        if self._modbus is not None:
            await self._modbus.shutdown()
        if self.ads is not None:
            self.ads.stop()
        if self.can_bus is not None:
            self.can_bus.shutdown()

    async def _open_modbus(self) -> None:
        """The PLC's Modbus TCP server, listening when this returns: a port already taken (another sim, a
        real PLC's gateway) is an error here, not a rig that says it serves on a port something else
        answers on (pymodbus's serve_forever only logs it, from a task nobody awaits)."""
        self._modbus = make_server(self.plc, self.host, self.modbus_port,
                                   on_access=lambda *a: self.fault_injection["drop_plc_link"])
        try:
            await self._modbus.serve_forever(background=True)
        except RuntimeError:
            raise RuntimeError(f"the PLC's Modbus TCP server cannot listen on {self.host}:{self.modbus_port}: "
                               "the port is in use (another simulated rig or service?) or the address is not "
                               "this machine's") from None

    def _start_modbus(self) -> None:
        self._modbus = make_server(self.plc, self.host, self.modbus_port,
                                   on_access=lambda *a: self.fault_injection["drop_plc_link"])
        asyncio.get_running_loop().create_task(self._modbus.serve_forever())

    async def _plc_link(self) -> None:
        """Cut the PLC's TCP server when asked, and restore it when the cut is over."""
        if self.fault_injection["cut_plc_link_s"] > 0 and self._modbus is not None:
            self._plc_cut_until = self.plc.time_s + self.fault_injection["cut_plc_link_s"]
            self.fault_injection["cut_plc_link_s"] = 0.0
            server, self._modbus = self._modbus, None
            await server.shutdown()
        elif self._modbus is None and self._plc_cut_until is not None and self.plc.time_s >= self._plc_cut_until:
            self._plc_cut_until = None
            self._start_modbus()

    async def _on_stream_client(self, reader, writer) -> None:
        if self.plc.time_s < self._disconnected_until:  # a disconnected sensor: nobody answers
            writer.close()
            return
        self._clients.add(writer)
        try:
            await reader.read()  # until the client goes away
        except (ConnectionError, asyncio.CancelledError):
            pass  # a client that vanished (killed, reset), or the rig stopping: nothing to report
        finally:
            self._clients.discard(writer)

    # -- physics and streaming -------------------------------------------------------------------------
    async def _physics(self) -> None:
        loop = asyncio.get_running_loop()
        t_wall0 = loop.time()
        rig_t = 0.0
        while True:
            await asyncio.sleep(self.tick_s)
            target = (loop.time() - t_wall0) * self.speed
            dt = target - rig_t
            if dt <= 0:
                continue
            await self._plc_link()
            if self.ads is not None:
                self.ads.cycle()
            step = min(dt, self.max_step_s())
            self.lost_rig_s += dt - step
            first, samples = self.plc.advance(step)
            rig_t = target
            if samples.size:
                if not self._pending.size:
                    self._pending_first = first
                self._pending = np.vstack([self._pending, samples])
            await self._send_frames()

    def max_step_s(self) -> float:
        """The most rig time one tick may simulate (s): twice a tick's share (a late tick on a loaded
        machine is caught up), and no more than a quarter of the watchdog, though never less than one
        tick's share (the rig keeps its speed whatever the watchdog).

        A stall of this process (the loop, or the whole process, not scheduled for a while) is time
        the rig does not see: what a tick would simulate beyond this is dropped (lost_rig_s adds it up).
        Otherwise the first tick after a 0.5 s stall at 10x would simulate 5 s at once, and the next,
        10 ms later, would find the heartbeat silent for 5 s unless the client's beat had arrived in
        between. A beat queued on the socket during the stall is read in that gap. A client stalled with
        the simulator (the same process, or a starved machine) may send it only later. That is a
        spurious watchdog fault: a real PLC, whose scan cannot stall like that, never raises it. A
        client that really falls silent is still caught. It is silent in wall time while ticks go on at
        their normal pace, and the rig's clock keeps `speed` through that."""
        tick = self.tick_s * self.speed
        return max(tick, min(2.0 * tick, self.plc.config.limits.watchdog_s / 4))

    def _send_can(self, counts: np.ndarray, flags: int) -> None:
        import can  # only rigs with a CAN output need python-can loaded

        for payload in can_frames.encode(self._can_counter, counts, flags):
            if self.fault_injection["drop_can_frames"] > 0:
                self.fault_injection["drop_can_frames"] -= 1
                continue
            self.can_bus.send(can.Message(arbitration_id=can_frames.BASE_ID + self.can_node, data=payload,
                                          is_extended_id=False))
        self._can_counter = (self._can_counter + counts.shape[0]) & 0xFFFF

    async def _send_frames(self) -> None:
        n = self.frame_samples
        fs = self.plc.config.fs_hz
        while self._pending.shape[0] >= n:
            block, self._pending = self._pending[:n], self._pending[n:]
            first, self._pending_first = self._pending_first, self._pending_first + n
            if self.fault_injection["disconnect_s"] > 0:
                self._disconnected_until = self.plc.time_s + self.fault_injection["disconnect_s"]
                self.fault_injection["disconnect_s"] = 0.0
                for w in list(self._clients):
                    w.close()
                self._clients.clear()
            if self.fault_injection["stuck"]:
                if self._stuck_value is None:
                    self._stuck_value = block[:1].copy()
                block = np.repeat(self._stuck_value, n, axis=0)
            else:
                self._stuck_value = None
            if self.fault_injection["saturate"]:
                block = block.copy()
                block[:, 1] = np.where(block[:, 1] >= 0, 2.0, -2.0) * 32767 / self.sensitivity
            counts, flags = frames.to_counts(block, self.sensitivity)
            if self.redundant_sensors:
                noise = self.plc.config.mass_sensor.noise_ms2
                second = block + self._rng.normal(0.0, noise, block.shape)
                data_counts = np.hstack([counts, frames.to_counts(second, self.sensitivity)[0]])
            else:
                data_counts = counts
            data = frames.encode(self._seq, int(round(first / fs * 1e6)), data_counts, flags)
            self._seq += 1
            if self.can_bus is not None:
                self._send_can(counts, flags)
            if self.fault_injection["drop_frames"] > 0:
                self.fault_injection["drop_frames"] -= 1
                continue
            if self.fault_injection["corrupt_frames"] > 0:
                self.fault_injection["corrupt_frames"] -= 1
                data = data[:20] + bytes([data[20] ^ 0xFF]) + data[21:]
            for w in list(self._clients):
                try:
                    w.write(data)
                except (ConnectionError, RuntimeError):
                    self._clients.discard(w)
            for w in list(self._clients):
                try:
                    await w.drain()
                except (ConnectionError, RuntimeError):
                    self._clients.discard(w)
