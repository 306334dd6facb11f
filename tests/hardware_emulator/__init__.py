"""An emulated Universal Robots controller for tests: the real ur_rtde client connects to it.

See `emulator.EmulatedUR` (sockets, clock, faults), `controller` (robot state and one control
cycle), `protocols` (RTDE, dashboard, script ports), `script` (ur_rtde's control-script register
protocol), `motion` (UR's moveL trapezoid), `regulator` (a vacuum regulator on the analog I/O).
"""

from .controller import CB3, ESERIES, ControllerConfig
from .emulator import EmulatedUR, EmulatorError
from .piano import PianoConfig
from .regulator import VacuumRegulator

__all__ = ["CB3", "ESERIES", "ControllerConfig", "EmulatedUR", "EmulatorError", "PianoConfig",
           "VacuumRegulator"]
