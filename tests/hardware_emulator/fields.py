"""RTDE field names and types, as the UR controller publishes them (UR's RTDE guide).

Outputs are what the controller streams in data packages; inputs are what a client may write.
Each type maps to a big-endian struct code. A field that needs a newer controller than the
emulated one is unknown to it, as on a real controller (the setup answer says NOT_FOUND).
"""

from __future__ import annotations

from dataclasses import dataclass

# RTDE type name → struct codes (big-endian, no padding).
STRUCT_CODES: dict[str, str] = {
    "BOOL": "?",
    "UINT8": "B",
    "UINT32": "I",
    "UINT64": "Q",
    "INT32": "i",
    "DOUBLE": "d",
    "VECTOR3D": "3d",
    "VECTOR6D": "6d",
    "VECTOR6INT32": "6i",
    "VECTOR6UINT32": "6I",
}
VECTOR_SIZES = {"VECTOR3D": 3, "VECTOR6D": 6, "VECTOR6INT32": 6, "VECTOR6UINT32": 6}

Version = tuple[int, int]


@dataclass(frozen=True)
class Field:
    """One RTDE field: its type and the first CB3 / e-Series versions that have it."""

    type: str
    cb3: Version | None = (3, 4)
    eseries: Version | None = (5, 0)

    def available(self, version: tuple[int, int, int, int]) -> bool:
        first = self.cb3 if version[0] < 5 else self.eseries
        return first is not None and version[:2] >= first


_V6 = "VECTOR6D"
OUTPUTS: dict[str, Field] = {
    "timestamp": Field("DOUBLE"),
    "target_q": Field(_V6), "target_qd": Field(_V6), "target_qdd": Field(_V6),
    "target_current": Field(_V6), "target_moment": Field(_V6),
    "actual_q": Field(_V6), "actual_qd": Field(_V6), "actual_current": Field(_V6),
    "joint_control_output": Field(_V6),
    "actual_TCP_pose": Field(_V6), "actual_TCP_speed": Field(_V6), "actual_TCP_force": Field(_V6),
    "target_TCP_pose": Field(_V6), "target_TCP_speed": Field(_V6),
    "actual_digital_input_bits": Field("UINT64"),
    "joint_temperatures": Field(_V6),
    "actual_execution_time": Field("DOUBLE"),
    "robot_mode": Field("INT32"),
    "joint_mode": Field("VECTOR6INT32"),
    "safety_mode": Field("INT32"),
    "safety_status": Field("INT32", cb3=None, eseries=(5, 4)),
    "actual_tool_accelerometer": Field("VECTOR3D"),
    "speed_scaling": Field("DOUBLE"),
    "target_speed_fraction": Field("DOUBLE"),
    "actual_momentum": Field("DOUBLE"),
    "actual_main_voltage": Field("DOUBLE"),
    "actual_robot_voltage": Field("DOUBLE"),
    "actual_robot_current": Field("DOUBLE"),
    "actual_joint_voltage": Field(_V6),
    "actual_digital_output_bits": Field("UINT64"),
    "runtime_state": Field("UINT32"),
    "elbow_position": Field("VECTOR3D", cb3=(3, 5)),
    "elbow_velocity": Field("VECTOR3D", cb3=(3, 5)),
    "robot_status_bits": Field("UINT32"),
    "safety_status_bits": Field("UINT32"),
    "analog_io_types": Field("UINT32"),
    "standard_analog_input0": Field("DOUBLE"),
    "standard_analog_input1": Field("DOUBLE"),
    "standard_analog_output0": Field("DOUBLE"),
    "standard_analog_output1": Field("DOUBLE"),
    "io_current": Field("DOUBLE"),
    "tool_mode": Field("UINT32"),
    "tool_analog_input_types": Field("UINT32"),
    "tool_analog_input0": Field("DOUBLE"),
    "tool_analog_input1": Field("DOUBLE"),
    "tool_output_voltage": Field("INT32"),
    "tool_output_current": Field("DOUBLE"),
    "tool_temperature": Field("DOUBLE"),
    "tcp_force_scalar": Field("DOUBLE"),
    "output_bit_registers0_to_31": Field("UINT32"),
    "output_bit_registers32_to_63": Field("UINT32"),
    "payload": Field("DOUBLE", cb3=(3, 11), eseries=(5, 6)),
    "payload_cog": Field("VECTOR3D", cb3=(3, 11), eseries=(5, 6)),
    "payload_inertia": Field(_V6, cb3=(3, 15), eseries=(5, 11)),
    "ft_raw_wrench": Field(_V6, cb3=None, eseries=(5, 9)),
    "script_control_line": Field("UINT32", cb3=(3, 14), eseries=(5, 9)),
}
INPUTS: dict[str, Field] = {
    "speed_slider_mask": Field("UINT32"),
    "speed_slider_fraction": Field("DOUBLE"),
    "standard_digital_output_mask": Field("UINT8"),
    "standard_digital_output": Field("UINT8"),
    "configurable_digital_output_mask": Field("UINT8"),
    "configurable_digital_output": Field("UINT8"),
    "tool_digital_output_mask": Field("UINT8"),
    "tool_digital_output": Field("UINT8"),
    "standard_analog_output_mask": Field("UINT8"),
    "standard_analog_output_type": Field("UINT8"),
    "standard_analog_output_0": Field("DOUBLE"),
    "standard_analog_output_1": Field("DOUBLE"),
    "input_bit_registers0_to_31": Field("UINT32"),
    "input_bit_registers32_to_63": Field("UINT32"),
    "external_force_torque": Field(_V6, cb3=(3, 3), eseries=(5, 0)),
}
# General-purpose registers: 0-23 from CB3 3.4 / e-Series 5.0, 24-47 from 3.9 / 5.3.
for _i in range(48):
    _upper = _i >= 24
    _reg = {"cb3": (3, 9) if _upper else (3, 4), "eseries": (5, 3) if _upper else (5, 0)}
    OUTPUTS[f"output_int_register_{_i}"] = Field("INT32", **_reg)  # type: ignore[arg-type]
    OUTPUTS[f"output_double_register_{_i}"] = Field("DOUBLE", **_reg)  # type: ignore[arg-type]
    OUTPUTS[f"input_int_register_{_i}"] = Field("INT32", **_reg)  # type: ignore[arg-type]
    OUTPUTS[f"input_double_register_{_i}"] = Field("DOUBLE", **_reg)  # type: ignore[arg-type]
    INPUTS[f"input_int_register_{_i}"] = Field("INT32", **_reg)  # type: ignore[arg-type]
    INPUTS[f"input_double_register_{_i}"] = Field("DOUBLE", **_reg)  # type: ignore[arg-type]


def field_type(table: dict[str, Field], name: str, version: tuple[int, int, int, int]) -> str:
    """The field's RTDE type on this controller version, or NOT_FOUND."""
    found = table.get(name)
    return found.type if found is not None and found.available(version) else "NOT_FOUND"


def struct_format(types: list[str]) -> str:
    """The big-endian struct format of a recipe's values (after the recipe id byte)."""
    return ">" + "".join(STRUCT_CODES[t] for t in types)
