"""The three protocols the emulated controller answers: RTDE, the dashboard, the script ports.

Each client connection gets a handler; the network thread feeds it bytes (`feed`), the cycle
thread asks RTDE handlers for their data package (`package`). Replies go through `send`,
which the network layer serialises per connection.

RTDE (port 30004): every message is `uint16 size, uint8 type, payload` (big-endian, the size
counts the header). The handler negotiates the protocol version (1 or 2), answers the
controller version, accepts one output recipe (v2: a double frequency, then comma-separated
names) and any number of input recipes (names; a field another client already writes is
IN_USE, an unknown one NOT_FOUND), starts and pauses the stream, and applies input data
packages (`U` + recipe id + values) to the controller. Output packages go out at the recipe's
frequency, at most once per control cycle.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from .controller import (
    POLYSCOPE,
    ROBOT_MODE_NAMES,
    RUNNING,
    RUNTIME_NAMES,
    SAFETY_NAMES,
    Controller,
)
from .fields import INPUTS, OUTPUTS, VECTOR_SIZES, field_type, struct_format

V, v, M, U, O, I, S, P = (ord(c) for c in "VvMUOISP")  # noqa: E741
HEADER = struct.Struct(">HB")

Send = Callable[[bytes], None]


def message(kind: int, payload: bytes = b"") -> bytes:
    return HEADER.pack(HEADER.size + len(payload), kind) + payload


@dataclass
class OutputRecipe:
    names: list[str]
    sizes: list[int]
    packer: struct.Struct
    frequency_hz: float


@dataclass
class InputRecipe:
    names: list[str]
    sizes: list[int]
    unpacker: struct.Struct


class RtdeHandler:
    """One RTDE client."""

    def __init__(self, controller: Controller, send: Send, owners: dict[str, RtdeHandler],
                 log: list[dict[str, Any]]) -> None:
        self.c = controller
        self.send = send
        self.owners = owners  # input field → the handler that writes it (shared by all)
        self.log = log
        self.buffer = bytearray()
        self.protocol = 1
        self.output: OutputRecipe | None = None
        self.inputs: dict[int, InputRecipe] = {}
        self.started = False
        self._phase = 0.0
        self.packages_sent = 0

    def feed(self, data: bytes) -> None:
        self.buffer += data
        while len(self.buffer) >= HEADER.size:
            size, kind = HEADER.unpack_from(self.buffer)
            if size < HEADER.size:
                raise ValueError(f"bad RTDE message size {size}")
            if len(self.buffer) < size:
                return
            payload = bytes(self.buffer[HEADER.size:size])
            del self.buffer[:size]
            self._handle(kind, payload)

    def _handle(self, kind: int, payload: bytes) -> None:
        if kind == V:
            (version,) = struct.unpack(">H", payload[:2])
            ok = version in (1, 2)
            if ok:
                self.protocol = version
            self.send(message(V, bytes([ok])))
        elif kind == v:
            self.send(message(v, struct.pack(">IIII", *self.c.config.version)))
        elif kind == O:
            self._setup_outputs(payload)
        elif kind == I:
            self._setup_inputs(payload)
        elif kind == S:
            ok = self.output is not None
            self.send(message(S, bytes([ok])))
            self.started = ok
        elif kind == P:
            self.started = False
            self.send(message(P, bytes([1])))
        elif kind == U:
            recipe = self.inputs.get(payload[0]) if payload else None
            if recipe is None:
                self.log.append({"event": "unknown input recipe", "payload": payload[:1]})
                return
            flat = recipe.unpacker.unpack(payload[1:1 + recipe.unpacker.size])
            values: dict[str, Any] = {}
            i = 0
            for name, size in zip(recipe.names, recipe.sizes, strict=True):
                values[name] = flat[i] if size == 1 else flat[i:i + size]
                i += size
            with self.c.lock:
                self.c.apply_inputs(values)
        elif kind == M:
            pass  # text messages from clients are logged by a real controller; nothing to do

    @staticmethod
    def _names(text: bytes) -> list[str]:
        # ur_rtde ends its lists with a comma; a real controller accepts that.
        return [n for n in text.decode().split(",") if n]

    def _setup_outputs(self, payload: bytes) -> None:
        if self.protocol >= 2:
            (frequency,) = struct.unpack(">d", payload[:8])
            names = self._names(payload[8:])
        else:
            frequency, names = self.c.config.loop_hz, self._names(payload)
        version = self.c.config.version
        types = [field_type(OUTPUTS, n, version) for n in names]
        ok = "NOT_FOUND" not in types and 0 < frequency
        self.log.append({"event": "output setup", "frequency_hz": frequency, "names": names,
                         "types": types})
        if ok:
            self.output = OutputRecipe(names, [VECTOR_SIZES.get(t, 1) for t in types],
                                       struct.Struct(struct_format(types)), frequency)
        self.send(message(O, bytes([1 if ok else 0]) + ",".join(types).encode()))

    def _setup_inputs(self, payload: bytes) -> None:
        names = self._names(payload)
        version = self.c.config.version
        types = [field_type(INPUTS, n, version) for n in names]
        types = ["IN_USE" if self.owners.get(n, self) is not self and t != "NOT_FOUND" else t
                 for n, t in zip(names, types, strict=True)]
        ok = not any(t in ("IN_USE", "NOT_FOUND") for t in types)
        recipe_id = 0
        if ok:
            recipe_id = len(self.inputs) + 1
            self.inputs[recipe_id] = InputRecipe(names, [VECTOR_SIZES.get(t, 1) for t in types],
                                                 struct.Struct(struct_format(types)))
            for n in names:
                self.owners[n] = self
        self.log.append({"event": "input setup", "names": names, "types": types,
                         "recipe": recipe_id})
        self.send(message(I, bytes([recipe_id]) + ",".join(types).encode()))

    def release(self) -> None:
        """The client is gone: its input fields are free again."""
        for name in [n for n, h in self.owners.items() if h is self]:
            del self.owners[name]

    def package(self) -> bytes | None:
        """This cycle's data package, if one is due (called with the controller locked)."""
        recipe = self.output
        if not self.started or recipe is None:
            return None
        # At most one package per control cycle: a faster recipe gets the loop rate.
        self._phase += min(recipe.frequency_hz / self.c.config.loop_hz, 1.0)
        if self._phase < 1.0 - 1e-9:
            return None
        self._phase -= 1.0
        flat: list[Any] = []
        for name, size in zip(recipe.names, recipe.sizes, strict=True):
            value = self.c.output(name)
            if size == 1:
                flat.append(value)
            else:
                flat.extend(value)
        self.packages_sent += 1
        return message(U, b"\x01" + recipe.packer.pack(*flat))


class DashboardHandler:
    """The dashboard server's line protocol (port 29999)."""

    WELCOME = b"Connected: Universal Robots Dashboard Server\n"

    def __init__(self, controller: Controller, send: Send, close: Callable[[], None]) -> None:
        self.c = controller
        self.send = send
        self.close = close
        self.buffer = b""
        self.lines: list[str] = []
        send(self.WELCOME)

    def feed(self, data: bytes) -> None:
        self.buffer += data
        while b"\n" in self.buffer:
            raw, self.buffer = self.buffer.split(b"\n", 1)
            line = raw.decode(errors="replace").strip()
            self.lines.append(line)
            with self.c.lock:
                reply = self._answer(line)
            self.send((reply + "\n").encode())
            if line == "quit":
                self.close()
                return

    def _eseries_from(self, minor: int) -> bool:
        major, have = self.c.config.version[:2]
        return major >= 5 and have >= minor

    def _answer(self, line: str) -> str:
        c = self.c
        cmd = line.lower()
        if cmd == "polyscopeversion":
            return POLYSCOPE[c.config.generation]
        if cmd == "robotmode":
            return f"Robotmode: {ROBOT_MODE_NAMES.get(c.robot_mode, c.robot_mode)}"
        if cmd == "safetymode":
            return f"Safetymode: {SAFETY_NAMES.get(c.safety_mode, c.safety_mode)}"
        if cmd == "safetystatus":
            return f"Safetystatus: {SAFETY_NAMES.get(c.safety_mode, c.safety_mode)}"
        if cmd == "programstate":
            name = "rtde_control" if c.script is not None else "<unnamed>"
            return f"{RUNTIME_NAMES.get(c.runtime, 'STOPPED')} {name}"
        if cmd == "running":
            return f"Program running: {str(c.runtime == 2).lower()}"
        if cmd == "get robot model":
            return c.config.model
        if cmd == "get serial number" and self._eseries_from(6):
            return c.config.serial_number
        if cmd == "is in remote control" and self._eseries_from(6):
            return str(c.config.remote_control).lower()
        if cmd == "get loaded program":
            return "No program loaded"
        if cmd == "stop":
            c.stop_program()  # answered "Stopped" also when nothing ran (ur_rtde relies on it)
            return "Stopped"
        if cmd == "pause":
            return "Pausing program" if c.pause_program() else "Failed to execute: pause"
        if cmd == "play":
            return "Starting program" if c.play_program() else "Failed to execute: play"
        if cmd == "power on":
            c.robot_mode = max(c.robot_mode, 5)
            return "Powering on"
        if cmd == "power off":
            c.robot_mode = 3
            c.stop_program()
            return "Powering off"
        if cmd == "brake release":
            if c.robot_mode >= 4:
                c.robot_mode = RUNNING
            return "Brake releasing"
        if cmd == "unlock protective stop":
            if c.unlock_protective_stop():
                return "Protective stop releasing"
            return ("Cannot unlock protective stop until 5s after occurrence. Always inspect "
                    "cause of protective stop before unlocking")
        if cmd in ("close safety popup", "close popup"):
            return "closing safety popup" if "safety" in cmd else "closing popup"
        if cmd == "quit":
            return "Disconnected"
        if cmd.startswith("addtolog ") or cmd.startswith("popup "):
            return "Added log message" if cmd.startswith("addtolog") else "showing popup"
        return f"could not understand: '{line}'"


_PROGRAM_END = re.compile(rb"^end[ \t]*\r?\n", re.MULTILINE)


class ScriptHandler:
    """A script port (30001-30003): URScript programs, each `def ...():` up to its `end`."""

    def __init__(self, controller: Controller) -> None:
        self.c = controller
        self.buffer = b""

    def feed(self, data: bytes) -> None:
        self.buffer += data
        while True:
            found = _PROGRAM_END.search(self.buffer)
            if found is None:
                return
            program, self.buffer = self.buffer[:found.end()], self.buffer[found.end():]
            with self.c.lock:
                self.c.load_program(program.decode(errors="replace"))

