"""The part of ur_rtde's control script (`rtde_control.script`) that the emulator executes.

ur_rtde uploads a URScript program to the controller and then talks to it through RTDE
registers (offsets 0 or 24, injected into the script text):

- `input_int_register_0` holds the command; the script's main loop runs once per controller
  cycle: command 0 means idle (it answers "ready", `output_int_register_0 = 1`); any other
  command is processed once and answered "done" (`= 2`) until the client clears it to 0.
  A synchronous move blocks the main loop until the arm arrives.
- `input_int_register_1` is the "asynchronous" flag; poses, speeds and accelerations come in
  `input_double_register_0..7`.
- `output_int_register_2` is the async status word: bits 24-30 an operation id (bumped when a
  move or stop thread starts), bits 16-23 a write counter, bit 15 "running", bits 0-14 progress.
- `output_int_register_1` answers queries (1/0 for `isPoseWithinSafetyLimits`).

Emulated commands: moveL (3, sync/async), stopL/stopJ (33/34, sync/async), isPoseWithin-
SafetyLimits (36), teach mode (18/19), triggerProtectiveStop (31), watchdog (35/99) and
stopScript (255). Anything else is recorded in `Controller.unsupported` and answered "done"
without effect, so a test can fail on it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import TYPE_CHECKING

from .motion import LinearMove, Stop

if TYPE_CHECKING:
    from .controller import Controller

READY, DONE = 1, 2
MOVEL, TEACH, END_TEACH, PROTECTIVE_STOP = 3, 18, 19, 31
STOPL, STOPJ, SET_WATCHDOG, POSE_WITHIN, WATCHDOG, STOP_SCRIPT = 33, 34, 35, 36, 99, 255
# Commands the script processes every cycle without the ready/done handshake.
REALTIME = frozenset({6, 9, 10, 11, 24, 25, 26, 27, 38, 58})
KILL_DECELERATION_MPS2 = 10.0  # a killed move thread: the controller brakes hard
_OFFSET = re.compile(r"reg_offset_(float|int)\s*=\s*#[^\n]*\n\s*(\d+)")


def register_offsets(program: str) -> tuple[int, int]:
    """(float offset, int offset) injected by ur_rtde; 0 when absent."""
    found = {kind: int(value) for kind, value in _OFFSET.findall(program)}
    return found.get("float", 0), found.get("int", 0)


@dataclass
class _Thread:
    kind: str  # "move" | "stop"
    started: bool = False
    motion: LinearMove | Stop | None = None
    target: tuple[float, ...] = ()
    speed: float = 0.0
    acceleration: float = 0.0


class ControlScript:
    """One running instance of the uploaded control script."""

    def __init__(self, controller: Controller, program: str) -> None:
        self.c = controller
        self.offset_float, self.offset_int = register_offsets(program)
        self.executing = False
        self.blocking: LinearMove | Stop | None = None
        self.thread: _Thread | None = None
        self.wr_count = 0
        self.op_id = 0
        self.terminated = False
        self._write_progress(-1)  # reset_async_progress()
        self._out_int(0, READY)

    # -- registers -------------------------------------------------------------------------
    def _in_int(self, i: int) -> int:
        return self.c.in_int[i + self.offset_int]

    def _in_double(self, i: int) -> float:
        return self.c.in_double[i + self.offset_float]

    def _out_int(self, i: int, value: int) -> None:
        self.c.out_int[i + self.offset_int] = int(value)

    def _write_progress(self, value: int) -> None:
        """The script's write_async_progress_register()."""
        self.wr_count += 1
        if self.wr_count > 127:
            self.wr_count = 0
        if value == 0:
            self.op_id += 1
            if self.op_id > 127:
                self.op_id = 0
        word = self.wr_count * 65536 + self.op_id * 16777216
        if value >= 0:
            word += min(value, 32767) + 32768
        self._out_int(2, word)

    # -- one controller cycle --------------------------------------------------------------
    def step(self) -> None:
        """The main loop's body for this cycle, then the helper threads."""
        self._main()
        self._threads()

    def _main(self) -> None:
        if self.blocking is not None:  # inside process_cmd: a synchronous move or stop
            if not self.blocking.done:
                return
            self.blocking = None
            self._out_int(0, DONE)
            return
        cmd = self._in_int(0)
        if cmd in REALTIME:
            self._unsupported(cmd)
            self._out_int(0, READY)
        elif cmd == 0:
            self.executing = False
            self._out_int(0, READY)
        elif not self.executing:
            self.executing = True
            self._process(cmd)
            if self.blocking is None and not self.terminated:
                self._out_int(0, DONE)

    def _threads(self) -> None:
        thread = self.thread
        if thread is None:
            return
        if not thread.started:  # a thread runs from the cycle after `run`
            thread.started = True
            self._write_progress(0)
            if thread.kind == "move":
                thread.motion = self.c.start_move(thread.target, thread.speed, thread.acceleration)
            else:
                thread.motion = self.c.start_stop(thread.acceleration)
            return
        if thread.motion is None or thread.motion.done:
            self.thread = None
            self._write_progress(-1)

    # -- commands --------------------------------------------------------------------------
    def _process(self, cmd: int) -> None:
        c = self.c
        c.commands.append(cmd)
        if cmd == MOVEL:
            pose = tuple(self._in_double(i) for i in range(6))
            speed, acceleration = self._in_double(6), self._in_double(7)
            self._stop_async_move()
            if self._in_int(1) == 1:
                self.thread = _Thread("move", target=pose, speed=speed, acceleration=acceleration)
            else:
                self.blocking = c.start_move(pose, speed, acceleration)
        elif cmd in (STOPL, STOPJ):
            self._stop(cmd)
        elif cmd == POSE_WITHIN:
            pose = tuple(self._in_double(i) for i in range(6))
            self._out_int(1, 1 if c.within_safety_limits(pose) else 0)
        elif cmd == TEACH:
            c.teach_mode = True
        elif cmd == END_TEACH:
            c.teach_mode = False
        elif cmd == PROTECTIVE_STOP:
            c.protective_stop("triggered by the control script")
        elif cmd in (SET_WATCHDOG, WATCHDOG):
            pass
        elif cmd == STOP_SCRIPT:
            self.terminate()
        else:
            self._unsupported(cmd)

    def _stop(self, cmd: int) -> None:
        deceleration = self._in_double(0)
        was_stopping = self.thread is not None and self.thread.kind == "stop"
        if was_stopping:  # a running stop thread is restarted with the new parameters
            self.thread = None
            self._write_progress(-1)
        else:
            self._stop_async_move()
        if self._in_int(1) == 1:
            self.thread = _Thread("stop", acceleration=deceleration)
        else:
            self.blocking = self.c.start_stop(deceleration)

    def _stop_async_move(self) -> None:
        """Kill a running move thread; it cannot signal its end, so the killer does."""
        if self.thread is not None and self.thread.kind == "move":
            self.thread = None
            self.c.start_stop(KILL_DECELERATION_MPS2)
            self._write_progress(-1)

    def _unsupported(self, cmd: int) -> None:
        if cmd not in self.c.unsupported:
            self.c.unsupported.append(cmd)

    def terminate(self) -> None:
        """The script ends (stopScript, a dashboard stop, a new program): threads die with it."""
        self.terminated = True
        self.thread = None
        self.blocking = None
