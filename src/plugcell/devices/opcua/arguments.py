"""Process data ↔ OPC UA variants and method arguments (OPC 10000-3 §8.6, -6 §5.2.2.16).

A plugcell command declares its data as a type of appendix F.4 and an n-D size of
F.5; an OPC UA method argument declares a DataType, a ValueRank and
ArrayDimensions.  The mapping:

=================  ===========================================================
plugcell            OPC UA
=================  ===========================================================
Boolean/Byte        Boolean / Byte
Integer/Double      Int32 / Double
String              String
size ``(1,)``       ValueRank −1 (Scalar); a one-element array is accepted too
size ``(n,)``       ValueRank 1, ArrayDimensions ``[n]`` (``0`` for ``-1``: any)
size ``(m, n)``     ValueRank 2, ArrayDimensions ``[m, n]`` (a matrix variant)
size ``()``         ValueRank −2 (Any)
=================  ===========================================================

A value going out keeps its n-D shape in the variant's ``Dimensions``; a value
coming in is checked with the framework's own :func:`~plugcell.framework.data.to_data`
(same reasons as a plugcell sender would read) after its variant type is checked.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from asyncua import ua

from plugcell.devices.opcua.driver import DATA_TYPE_IDS
from plugcell.framework.data import DataError, describe, from_data, to_data
from plugcell.framework.messages import Command, Data, DataTypes

#: The variant type of each plugcell data type (Boolean, Byte, Int32, Double, String: the
#: built-in types of :data:`~plugcell.devices.opcua.driver.DATA_TYPE_IDS`).
VARIANT_TYPES: dict[DataTypes, ua.VariantType] = {
    data_type: ua.VariantType(number) for data_type, number in DATA_TYPE_IDS.items()}


class ArgumentError(ValueError):
    """An input argument that does not match the command; the message says why."""


def value_rank(size: tuple[int, ...]) -> tuple[int, list[int]]:
    """The ValueRank and ArrayDimensions of a declared F.5 size (table above)."""
    if size == ():
        return int(ua.ValueRank.Any), []
    if size == (1,):
        return int(ua.ValueRank.Scalar), []
    return len(size), [max(d, 0) for d in size]


def data_argument(
    name: str, data_type: DataTypes | None, size: tuple[int, ...], description: str = ""
) -> ua.Argument:
    """The ``ua.Argument`` declaring data of ``data_type``/``size``."""
    assert data_type is not None
    rank, dims = value_rank(size)
    arg = ua.Argument()
    arg.Name = name
    arg.DataType = ua.NodeId(VARIANT_TYPES[data_type].value)
    arg.ValueRank = rank
    arg.ArrayDimensions = dims
    arg.Description = ua.LocalizedText(description or describe(data_type, size))
    return arg


def string_argument(name: str, description: str) -> ua.Argument:
    """A scalar String argument (the ``Option`` of every command)."""
    arg = ua.Argument()
    arg.Name = name
    arg.DataType = ua.NodeId(ua.ObjectIds.String)
    arg.ValueRank = int(ua.ValueRank.Scalar)
    arg.Description = ua.LocalizedText(description)
    return arg


def input_arguments(command: Command) -> list[ua.Argument]:
    """``Option`` (String) and, if the command takes input, ``Data``."""
    args = [string_argument("Option", "the command's option (may be empty)")]
    if command.takes_input:
        args.append(
            data_argument(
                "Data", command.input_data_type, command.input_data_size,
                f"input {describe(command.input_data_type, command.input_data_size)}",
            )
        )
    return args


def option_of(variant: Any, command: str) -> str:
    """The ``Option`` argument as text (a Null variant reads as ``""``)."""
    if not isinstance(variant, ua.Variant) or variant.VariantType is ua.VariantType.Null:
        return ""
    if variant.VariantType is not ua.VariantType.String or variant.is_array:
        raise ArgumentError(
            f"{command}: argument Option must be a String, got {_variant_text(variant)}"
        )
    return variant.Value or ""


def input_value(variant: Any, command: Command) -> Data | None:
    """The ``Data`` argument checked against ``command``'s declaration, as a typed buffer."""
    if not command.takes_input:
        return None
    what = f"{command.name}: argument Data"
    declared = describe(command.input_data_type, command.input_data_size)
    if not isinstance(variant, ua.Variant) or variant.VariantType is ua.VariantType.Null:
        raise ArgumentError(f"{what}: {declared} expected, got nothing")
    assert command.input_data_type is not None
    expected = VARIANT_TYPES[command.input_data_type]
    if variant.VariantType is not expected:
        raise ArgumentError(
            f"{what}: {expected.name} expected ({declared}), got {_variant_text(variant)}"
        )
    value = variant.Value
    if command.input_data_size == (1,) and isinstance(value, list) and len(value) == 1:
        value = value[0]
    if isinstance(value, bytes | bytearray):  # a Byte array some stacks send as bytes
        value = np.frombuffer(value, np.uint8)
    try:
        return to_data(value, command.input_data_type, command.input_data_size, what)
    except DataError as exc:
        raise ArgumentError(str(exc)) from None


def data_variant(data: Data | None) -> ua.Variant:
    """A process's data as a variant: a scalar for size ``[1]``, else an n-D array."""
    if data is None:
        return ua.Variant()
    vtype = VARIANT_TYPES[data.type]
    arr = from_data(data)
    assert arr is not None
    if data.size == (1,):
        return ua.Variant(arr.reshape(-1)[0].item() if data.type is not DataTypes.String
                          else arr.reshape(-1)[0], vtype)
    flat = list(data.buffer) if data.type is DataTypes.Byte else arr.reshape(-1).tolist()
    dims = list(data.size) if len(data.size) > 1 else None
    return ua.Variant(flat, vtype, dims, is_array=True)


def empty_variant(data_type: DataTypes | None, size: tuple[int, ...]) -> ua.Variant:
    """The initial value of a ``Data`` variable before any data arrived (typed, empty)."""
    if data_type is None:
        return ua.Variant()
    vtype = VARIANT_TYPES[data_type]
    if size == (1,):
        zero: Any = {DataTypes.Boolean: False, DataTypes.String: ""}.get(data_type, 0)
        if data_type is DataTypes.Double:
            zero = 0.0
        return ua.Variant(zero, vtype)
    return ua.Variant([], vtype, is_array=True)


def _variant_text(variant: ua.Variant) -> str:
    name = variant.VariantType.name
    if variant.is_array:
        shape = variant.Dimensions or [len(variant.Value or [])]
        return f"{name}[{', '.join(map(str, shape))}]"
    return f"scalar {name}"
