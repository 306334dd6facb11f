"""Fixtures of the rig tests: a private JACK server (dummy driver) for the MIDI tests, skipped
when jackd is absent, and `ur_emulator`, the emulated UR controller (tests/hardware_emulator).

Each pytest process (each xdist worker) starts its own server under a unique name and points
`JACK_DEFAULT_SERVER` at it, so parallel workers never share or kill each other's server.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
import time
import uuid
from collections.abc import Iterator

import pytest
from hardware_emulator.fixtures import ur_emulator  # noqa: F401  (the emulated UR controller)

# Small periods keep the JACK MIDI delivery jitter (one period) near 1 ms.
JACK_RATE_HZ = 48_000
JACK_PERIOD_FRAMES = 64
STARTUP_WAIT_S = 15.0


def _jack_accepts_clients() -> bool:
    """True when a JACK MIDI client can connect to the server named in the environment."""
    try:
        import rtmidi
    except ImportError:
        return False
    if rtmidi.API_UNIX_JACK not in rtmidi.get_compiled_api():
        return False
    try:
        probe = rtmidi.MidiIn(rtapi=rtmidi.API_UNIX_JACK, name="pianobot-probe")
    except (rtmidi.SystemError, RuntimeError):
        return False
    probe.delete()
    return True


@pytest.fixture(scope="session")
def jack_server() -> Iterator[str]:
    """Start `jackd --no-realtime -d dummy` under a unique name; yield the server name."""
    jackd = shutil.which("jackd")
    if jackd is None:
        pytest.skip("jackd is not installed (Debian package jackd2)")
    try:
        import rtmidi
    except ImportError:
        pytest.skip("python-rtmidi is not installed")
    if rtmidi.API_UNIX_JACK not in rtmidi.get_compiled_api():
        pytest.skip("this python-rtmidi build has no JACK support")

    name = f"pianobot-test-{os.getpid()}-{uuid.uuid4().hex[:6]}"
    saved = {key: os.environ.get(key) for key in ("JACK_DEFAULT_SERVER", "JACK_NO_START_SERVER")}
    os.environ["JACK_DEFAULT_SERVER"] = name
    # Never let a client auto-start some other server behind our back.
    os.environ["JACK_NO_START_SERVER"] = "1"
    command = [jackd, "--no-realtime", "-n", name, "-d", "dummy",
               "-r", str(JACK_RATE_HZ), "-p", str(JACK_PERIOD_FRAMES)]
    # jackd logs to a file, not a pipe: a full pipe would block the server mid-session.
    log = tempfile.TemporaryFile()
    server = subprocess.Popen(
        command, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
    )
    try:
        deadline = time.monotonic() + STARTUP_WAIT_S
        while not _jack_accepts_clients():
            if server.poll() is not None:
                log.seek(0)
                output = log.read().decode(errors="replace").strip()
                pytest.skip(f"jackd exited at start: {output[-300:]}")
            if time.monotonic() > deadline:
                pytest.skip(f"jackd did not accept clients within {STARTUP_WAIT_S:.0f} s")
            time.sleep(0.1)
        yield name
    finally:
        server.terminate()
        try:
            server.wait(timeout=10)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait()
        log.close()
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
