"""Rig failures, sorted by what the runner may do about them."""

from __future__ import annotations


class RigError(Exception):
    """Any failure of a rig device."""


class ConnectionLost(RigError):
    """Transient: the link dropped. The runner reconnects and retries the trial."""


class SafetyStop(RigError):
    """A protective or emergency stop. Never retried: the run stops until an operator clears it."""


class SafetyViolation(RigError):
    """A target was refused before it was sent (outside the envelope or workspace)."""


class DeviceUnavailable(RigError):
    """A configured device could not be reached or set up at all."""
