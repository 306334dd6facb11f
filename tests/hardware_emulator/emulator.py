"""`EmulatedUR`: an emulated UR controller in its own process, driven from the test.

    with EmulatedUR(ControllerConfig(generation="cb3")) as ur:
        receive = rtde_receive.RTDEReceiveInterface(ur.host)
        ...
        ur.fail_on_move(2, "protective_stop", fraction=0.4)

The controller runs in a child process (`server.serve`) on its own 127.x.y.z address; the
test talks to it over a pipe. The child ends when the test calls `stop()` (or leaves the
`with` block), when the test process dies (the pipe closes), or after `lifetime_s` at the
latest — no instance outlives its test by more than that.
"""

from __future__ import annotations

import multiprocessing
import time
from collections.abc import Callable
from typing import Any

from .controller import ControllerConfig
from .piano import PianoConfig

START_TIMEOUT_S = 30.0
CALL_TIMEOUT_S = 30.0


class EmulatorError(RuntimeError):
    """The emulator process failed or did not answer."""


class EmulatedUR:
    """The test's handle on an emulated controller process."""

    def __init__(self, config: ControllerConfig | None = None, *, lifetime_s: float = 300.0,
                 piano: PianoConfig | None = None) -> None:
        self.config = config or ControllerConfig()
        self.lifetime_s = lifetime_s
        self.piano = piano
        self.host = ""
        self._process: Any = None
        self._conn: Any = None

    # -- life cycle --------------------------------------------------------------------------
    def start(self) -> EmulatedUR:
        from .server import serve

        context = multiprocessing.get_context("spawn")  # no fork of a threaded test process
        parent, child = context.Pipe()
        self._process = context.Process(target=serve, args=(self.config, child, self.lifetime_s),
                                        name="ur-emulator", daemon=True)
        self._process.start()
        child.close()
        self._conn = parent
        try:
            self.host = str(self._answer(START_TIMEOUT_S))
            if self.piano is not None:
                self.call("set_piano", self.piano)
        except BaseException:
            self.stop()  # never leave a half-started emulator behind
            raise
        return self

    def stop(self) -> None:
        """End the emulator process (waits for it; kills it if it does not end)."""
        if self._process is None:
            return
        try:
            self._conn.send(("stop", (), {}))
            self._conn.poll(5.0)
        except (OSError, EOFError):
            pass
        self._process.join(timeout=5.0)
        if self._process.is_alive():
            self._process.kill()
            self._process.join(timeout=5.0)
        self._conn.close()
        self._process = None

    def __enter__(self) -> EmulatedUR:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def alive(self) -> bool:
        return self._process is not None and self._process.is_alive()

    @property
    def paused(self) -> bool:
        """The program is paused (or pausing) on the emulated pendant."""
        return self.get("runtime") in (3, 4)

    @property
    def program_running(self) -> bool:
        return self.get("runtime") == 2

    def script_waiting(self) -> bool:
        """ur_rtde's control script waits for a new command. Until then it takes the command in
        its register for the one it is still answering (a synchronous move that a protective
        stop paused, say), and ignores a new one: a `stopScript` then waits 300 s in ur_rtde."""
        return bool(self.call("script_waiting"))

    # -- calls -------------------------------------------------------------------------------
    def call(self, name: str, *args: Any, **kwargs: Any) -> Any:
        if self._process is None:
            raise EmulatorError("the emulator is not running")
        self._conn.send((name, args, kwargs))
        return self._answer(CALL_TIMEOUT_S)

    def _answer(self, timeout_s: float) -> Any:
        if not self._conn.poll(timeout_s):
            raise EmulatorError(f"the emulator did not answer within {timeout_s:g} s")
        try:
            status, value = self._conn.recv()
        except EOFError as exc:
            raise EmulatorError("the emulator process ended") from exc
        if status != "ok":
            raise EmulatorError(value)
        return value

    # -- faults ------------------------------------------------------------------------------
    def protective_stop(self) -> None:
        self.call("protective_stop")

    def emergency_stop(self) -> None:
        self.call("emergency_stop")

    def pause(self) -> None:
        """The pendant's pause button."""
        self.call("pause")

    def resume(self) -> None:
        self.call("resume")

    def stop_program(self) -> None:
        """The pendant's stop button: the control script ends, the links stay up."""
        self.call("stop_program")

    def set_slider(self, fraction: float) -> None:
        self.call("set_slider", fraction)

    def drop_links(self, outage_s: float = 0.0) -> None:
        """Every connection closes; for `outage_s` new ones are refused."""
        self.call("drop_links", outage_s)

    def fail_on_move(self, nth: int, what: str, *, fraction: float = 0.5,
                     outage_s: float = 0.5) -> None:
        """When the nth move started from now has covered `fraction` of its path, do `what`
        (protective_stop | emergency_stop | pause | stop_program | drop_links)."""
        self.call("fail_on_move", nth, what, fraction=fraction, outage_s=outage_s)

    # -- reading back ------------------------------------------------------------------------
    def state(self, *names: str) -> dict[str, Any]:
        """Controller attributes: runtime, slider, pose, commands, unsupported, events, ..."""
        return dict(self.call("state", *names))

    def get(self, name: str) -> Any:
        return self.state(name)[name]

    def set_state(self, **values: Any) -> None:
        self.call("set_state", **values)

    def truth_between(self, t0_s: float, t1_s: float) -> list[tuple[float, tuple[float, ...]]]:
        """(controller timestamp, TCP pose) of every control cycle in [t0, t1]."""
        return list(self.call("truth_between", t0_s, t1_s))

    def output_frequencies(self) -> list[float]:
        """The rate each RTDE client asked for in its output recipe, in order."""
        return list(self.call("output_frequencies"))

    def counts(self) -> dict[str, Any]:
        return dict(self.call("counts"))

    def regulator_kpa(self) -> float | None:
        result = self.call("regulator_kpa")
        return None if result is None else float(result)

    def piano_events(self) -> list[tuple[float, str, int, int]]:
        return list(self.call("piano_events"))

    def wait_until(self, condition: Callable[[EmulatedUR], bool], timeout_s: float = 5.0) -> bool:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if condition(self):
                return True
            time.sleep(0.01)
        return False
