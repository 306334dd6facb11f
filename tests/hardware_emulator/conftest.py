"""The emulator's own tests use its fixtures."""

from hardware_emulator.fixtures import ur_emulator

__all__ = ["ur_emulator"]
