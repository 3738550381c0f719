"""`rclpy.parameter.Parameter`: a named, typed node parameter."""

from __future__ import annotations

from enum import IntEnum
from typing import Any


class Parameter:
    """`Parameter(name, type_=Parameter.Type.NOT_SET, value=None)`, type inferred if unset."""

    class Type(IntEnum):
        """As rclpy (values of rcl_interfaces/ParameterType)."""

        NOT_SET = 0
        BOOL = 1
        INTEGER = 2
        DOUBLE = 3
        STRING = 4
        BYTE_ARRAY = 5
        BOOL_ARRAY = 6
        INTEGER_ARRAY = 7
        DOUBLE_ARRAY = 8
        STRING_ARRAY = 9

        @classmethod
        def from_parameter_value(cls, value: Any) -> Parameter.Type:
            """The parameter type of a Python value.

            Raises:
                TypeError: a value no ROS parameter can hold.
            """
            if value is None:
                return cls.NOT_SET
            scalar = {bool: cls.BOOL, int: cls.INTEGER, float: cls.DOUBLE, str: cls.STRING}
            if type(value) in scalar:
                return scalar[type(value)]
            if isinstance(value, bytes):
                return cls.BYTE_ARRAY
            if isinstance(value, list | tuple) and value:
                arrays = {bool: cls.BOOL_ARRAY, int: cls.INTEGER_ARRAY,
                          float: cls.DOUBLE_ARRAY, str: cls.STRING_ARRAY}
                kinds = {type(v) for v in value}
                if len(kinds) == 1 and kinds <= arrays.keys():
                    return arrays[kinds.pop()]
            raise TypeError(f"no ROS parameter type holds {value!r}")

    def __init__(self, name: str, type_: Parameter.Type | None = None,
                 value: Any = None) -> None:
        self.name = name
        self.type_ = Parameter.Type.from_parameter_value(value) if type_ is None else type_
        self.value = value

    def __repr__(self) -> str:
        return f"Parameter({self.name!r}, {self.type_.name}, {self.value!r})"
