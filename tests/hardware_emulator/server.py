"""`ControllerServer`: the controller on its own loopback address, with its servers and clock.

It runs inside the emulator's own process (`emulator.EmulatedUR` starts it): ur_rtde's
constructors hold the GIL while they wait for the controller, so a controller in the test's
process could never answer them.

ur_rtde's ports are fixed (29999 dashboard, 30001-30003 scripts, 30004 RTDE), and several test
workers and engineers run tests on one machine at once, so every instance binds its own
127.x.y.z address (any address in 127/8 reaches Linux's loopback), chosen at random and
retried until every port binds.

Two threads per instance: the cycle thread steps the controller at its loop rate on the wall
clock (missed cycles are stepped without sending, as a busy controller skips packages) and
sends the RTDE packages; the network thread accepts clients and reads what they send. Both end
on `stop()`, at the latest `lifetime_s` after the start, so an instance a test forgot cannot
outlive the test session.
"""

from __future__ import annotations

import random
import selectors
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from typing import Any

from .controller import PAUSED, PLAYING, Controller, ControllerConfig, MoveFault
from .piano import EmulatedPiano, PianoConfig
from .protocols import DashboardHandler, RtdeHandler, ScriptHandler

DASHBOARD_PORT, RTDE_PORT = 29999, 30004
SCRIPT_PORTS = (30001, 30002, 30003)
MAX_CATCH_UP_CYCLES = 50  # behind by more than this, the clock jumps (the host stalled)
SEND_TIMEOUT_S = 1.0


@dataclass
class _Client:
    kind: str  # "rtde" | "dashboard" | "script"
    sock: socket.socket
    handler: Any
    lock: threading.Lock = field(default_factory=threading.Lock)
    closed: bool = False


class ControllerServer:
    """The emulated controller's sockets, threads and test-facing actions (one process)."""

    def __init__(self, config: ControllerConfig | None = None, *, lifetime_s: float = 300.0) -> None:
        self.config = config or ControllerConfig()
        self.controller = Controller(self.config)
        self.lifetime_s = lifetime_s
        self.host = ""
        self.rtde_log: list[dict[str, Any]] = []
        self.connections: dict[str, int] = {"rtde": 0, "dashboard": 0, "script": 0}
        self._owners: dict[str, RtdeHandler] = {}
        self._clients: list[_Client] = []
        self._listeners: dict[socket.socket, tuple[str, int]] = {}
        self._relisten_at: float | None = None
        self._stop = threading.Event()
        self._selector = selectors.DefaultSelector()
        self._threads: list[threading.Thread] = []
        self._clients_lock = threading.Lock()
        self._piano: EmulatedPiano | None = None

    # -- life cycle --------------------------------------------------------------------------
    def start(self) -> ControllerServer:
        self._bind()
        self._deadline = time.monotonic() + self.lifetime_s
        for name, target in (("cycle", self._cycle_loop), ("net", self._net_loop)):
            thread = threading.Thread(target=target, name=f"ur-emulator-{name}-{self.host}",
                                      daemon=True)
            thread.start()
            self._threads.append(thread)
        return self

    def stop(self) -> None:
        self._stop.set()
        for thread in self._threads:
            if thread is not threading.current_thread():
                thread.join(timeout=5.0)
        for sock in list(self._listeners):
            sock.close()
        self._listeners.clear()
        for client in list(self._clients):
            self._close(client)
        self._selector.close()

    def __enter__(self) -> ControllerServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def alive(self) -> bool:
        return any(t.is_alive() for t in self._threads)

    def _bind(self) -> None:
        rng = random.Random()
        for _ in range(200):
            host = f"127.{rng.randint(1, 254)}.{rng.randint(0, 255)}.{rng.randint(1, 254)}"
            opened: dict[socket.socket, tuple[str, int]] = {}
            try:
                for kind, port in (("dashboard", DASHBOARD_PORT), ("rtde", RTDE_PORT),
                                   *(("script", p) for p in SCRIPT_PORTS)):
                    opened[self._listen(host, port)] = (kind, port)
            except OSError:
                for sock in opened:
                    sock.close()
                continue
            self.host = host
            self._listeners = opened
            for sock in opened:
                self._selector.register(sock, selectors.EVENT_READ, ("listen", sock))
            return
        raise RuntimeError("no free loopback address for the UR emulator")

    def _close_listeners(self) -> None:
        for sock in list(self._listeners):
            try:
                self._selector.unregister(sock)
            except (KeyError, ValueError, OSError):
                pass
            sock.close()

    def _open_listeners(self) -> None:
        """Listen again on the same address (after an outage)."""
        reopened: dict[socket.socket, tuple[str, int]] = {}
        for kind, port in self._listeners.values():
            sock = self._listen(self.host, port)
            reopened[sock] = (kind, port)
            self._selector.register(sock, selectors.EVENT_READ, ("listen", sock))
        self._listeners = reopened

    @staticmethod
    def _listen(host: str, port: int) -> socket.socket:
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((host, port))
            sock.listen(8)
        except OSError:
            sock.close()
            raise
        sock.setblocking(False)
        return sock

    # -- the network thread ------------------------------------------------------------------
    def _net_loop(self) -> None:
        while not self._stop.is_set() and time.monotonic() < self._deadline:
            if self._relisten_at is not None and time.monotonic() >= self._relisten_at:
                self._relisten_at = None
                self._open_listeners()
            for key, _ in self._selector.select(timeout=0.02):
                tag, obj = key.data
                if tag == "listen":
                    self._accept(obj)
                else:
                    self._read(obj)
        self._stop.set()

    def _accept(self, listener: socket.socket) -> None:
        try:
            sock, _ = listener.accept()
        except OSError:
            return
        kind, _port = self._listeners[listener]
        sock.setblocking(True)
        sock.settimeout(SEND_TIMEOUT_S)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        client = _Client(kind, sock, None)

        def send(data: bytes) -> None:
            self._send(client, data)

        if kind == "rtde":
            client.handler = RtdeHandler(self.controller, send, self._owners, self.rtde_log)
        elif kind == "dashboard":
            client.handler = DashboardHandler(self.controller, send, lambda: self._close(client))
        else:
            client.handler = ScriptHandler(self.controller)
        self.connections[kind] += 1
        with self._clients_lock:
            self._clients.append(client)
        self._selector.register(sock, selectors.EVENT_READ, ("client", client))

    def _read(self, client: _Client) -> None:
        try:
            data = client.sock.recv(65536)
        except OSError:
            data = b""
        if not data:
            self._close(client)
            return
        try:
            client.handler.feed(data)
        except (ValueError, IndexError, UnicodeDecodeError) as exc:
            self.rtde_log.append({"event": "protocol error", "error": repr(exc)})
            self._close(client)

    def _send(self, client: _Client, data: bytes) -> None:
        with client.lock:
            if client.closed:
                return
            try:
                client.sock.sendall(data)
            except OSError:
                pass
            else:
                return
        self._close(client)

    def _close(self, client: _Client) -> None:
        with client.lock:
            if client.closed:
                return
            client.closed = True
        try:
            self._selector.unregister(client.sock)
        except (KeyError, ValueError, OSError):
            pass
        client.sock.close()
        if isinstance(client.handler, RtdeHandler):
            with self.controller.lock:
                client.handler.release()
        with self._clients_lock:
            if client in self._clients:
                self._clients.remove(client)

    # -- the cycle thread --------------------------------------------------------------------
    def _cycle_loop(self) -> None:
        period = self.controller.period_s
        next_s = time.monotonic() + period
        while not self._stop.is_set():
            left = next_s - time.monotonic()
            if left > 0:
                time.sleep(left)
            now = time.monotonic()
            if now > self._deadline:
                break
            behind = int((now - next_s) / period)
            if behind > MAX_CATCH_UP_CYCLES:  # the host stalled: let the clock jump
                next_s += behind * period
                behind = 0
            sends: list[tuple[_Client, bytes]] = []
            with self.controller.lock:
                for _ in range(behind):
                    self.controller.step()  # cycles the host missed: no packages
                self.controller.step()
                with self._clients_lock:
                    clients = [c for c in self._clients if isinstance(c.handler, RtdeHandler)]
                for client in clients:
                    package = client.handler.package()
                    if package is not None:
                        sends.append((client, package))
            for client, package in sends:
                self._send(client, package)
            next_s += (behind + 1) * period
        self._stop.set()

    # -- what a test does to the robot ------------------------------------------------------
    def protective_stop(self) -> None:
        with self.controller.lock:
            self.controller.protective_stop("injected by the test")

    def emergency_stop(self) -> None:
        with self.controller.lock:
            self.controller.emergency_stop()

    def pause(self) -> None:
        """As the pendant's pause button (or the dashboard's `pause`)."""
        with self.controller.lock:
            self.controller.pause_program()

    def resume(self) -> None:
        with self.controller.lock:
            self.controller.play_program()

    def stop_program(self) -> None:
        """As the pendant's stop button: the control script ends, the links stay up."""
        with self.controller.lock:
            self.controller.stop_program()

    def set_slider(self, fraction: float) -> None:
        with self.controller.lock:
            self.controller.slider = fraction

    def drop_links(self, outage_s: float = 0.0) -> None:
        """The network goes down: every connection closes, new ones are refused for
        `outage_s` (as when the controller's ports are unreachable)."""
        if outage_s > 0 and self._relisten_at is None:
            self._close_listeners()
            self._relisten_at = time.monotonic() + outage_s
        with self._clients_lock:
            clients = list(self._clients)
        for client in clients:
            self._close(client)

    def fail_on_move(self, nth: int, what: str, *, fraction: float = 0.5,
                     outage_s: float = 0.5) -> None:
        """When the nth move started from now has covered `fraction` of its path, do `what`:
        protective_stop | emergency_stop | pause | stop_program | drop_links."""
        actions: dict[str, Callable[[], None]] = {
            "protective_stop": lambda: self.controller.protective_stop("injected mid-move"),
            "emergency_stop": self.controller.emergency_stop,
            "pause": self.controller.pause_program,
            "stop_program": self.controller.stop_program,
            "drop_links": lambda: threading.Thread(
                target=self.drop_links, args=(outage_s,), daemon=True).start(),
        }
        with self.controller.lock:
            self.controller.faults.append(MoveFault(nth, fraction, actions[what]))

    # -- what a test reads back -------------------------------------------------------------
    @property
    def program_running(self) -> bool:
        return self.controller.runtime == PLAYING

    @property
    def paused(self) -> bool:
        return self.controller.runtime == PAUSED

    def script_waiting(self) -> bool:
        """The control script has answered its last command and seen the register cleared."""
        with self.controller.lock:
            script = self.controller.script
            return script is not None and script.blocking is None and not script.executing

    def pose(self) -> tuple[float, ...]:
        with self.controller.lock:
            return self.controller.pose

    def truth_between(self, t0_s: float, t1_s: float) -> list[tuple[float, tuple[float, ...]]]:
        """(controller timestamp, TCP pose) of every cycle with t0 <= timestamp <= t1."""
        with self.controller.lock:
            return [(t, p) for t, p in self.controller.truth if t0_s <= t <= t1_s]

    def timestamp(self) -> float:
        with self.controller.lock:
            return self.controller.timestamp

    def state(self, *names: str) -> dict[str, Any]:
        """Controller attributes by name (runtime, slider, pose, commands, events, ...)."""
        with self.controller.lock:
            return {n: _plain(getattr(self.controller, n)) for n in names}

    def set_state(self, **values: Any) -> None:
        with self.controller.lock:
            for name, value in values.items():
                setattr(self.controller, name, value)

    def regulator_kpa(self) -> float | None:
        with self.controller.lock:
            reg = self.controller.regulator
            return None if reg is None else reg.kpa

    def piano_events(self) -> list[tuple[float, str, int, int]]:
        with self.controller.lock:
            return list(self._piano.events) if self._piano is not None else []

    def set_piano(self, config: PianoConfig) -> None:
        piano = EmulatedPiano(config)
        with self.controller.lock:
            if self._piano is not None:
                self.controller.cycle_hooks.remove(self._piano)
                self._piano.close()
            self._piano = piano
            self.controller.cycle_hooks.append(piano)

    def counts(self) -> dict[str, Any]:
        return {"connections": dict(self.connections),
                "frequencies": self.output_frequencies(),
                "programs": len(self.controller.programs)}

    def output_frequencies(self) -> list[float]:
        """The frequency each RTDE client asked for in its output recipe."""
        return [e["frequency_hz"] for e in self.rtde_log if e["event"] == "output setup"]

    def wait_until(self, condition: Callable[[], bool], timeout_s: float = 5.0) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            with self.controller.lock:
                if condition():
                    return True
            time.sleep(0.005)
        return False


def _plain(value: Any) -> Any:
    """Something picklable and detached from the controller (copies of lists and deques)."""
    if isinstance(value, list | tuple) or hasattr(value, "maxlen"):
        return list(value)
    return value


def serve(config: ControllerConfig, conn: Connection, lifetime_s: float) -> None:
    """The emulator process: start the server, answer the test's calls, stop when told to,
    when the test process goes away, or when the lifetime is over."""
    server = ControllerServer(config, lifetime_s=lifetime_s).start()
    conn.send(("ok", server.host))
    try:
        while server.alive:
            if not conn.poll(0.2):
                continue
            try:
                name, args, kwargs = conn.recv()
            except (EOFError, OSError):
                break
            if name == "stop":
                break
            try:
                result = getattr(server, name)(*args, **kwargs)
            except Exception as exc:  # the test sees the error instead of a hang
                conn.send(("error", f"{type(exc).__name__}: {exc}"))
            else:
                conn.send(("ok", result))
    finally:
        server.stop()
        if server._piano is not None:
            server._piano.close()
        try:
            conn.send(("ok", "stopped"))
        except OSError:
            pass
