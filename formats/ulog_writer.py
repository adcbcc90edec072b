"""Writing PX4 ULog files (``.ulg``): header, formats, subscriptions and data.

Follows the ULog specification (PX4 user guide, "ULog File Format"): a 16-byte file
header (magic ``ULog``, version 1, start timestamp in µs), the flag-bits message, then the
definitions section (``I`` information, ``F`` formats), then the data section (``A``
add-logged subscriptions and ``D`` data). pyulog reads what this writes; its own
``write_ulog`` only re-writes a file it has parsed.

Formats are given as PX4 writes them: ``"uint64_t timestamp;float[4] q;"``, nested types
by name (``"esc_report[8] esc;"``). Data rows are flattened field values keyed the way
pyulog names them (``"q[0]"``, ``"esc[2].esc_rpm"``); a missing field is written as 0.
"""

from __future__ import annotations

import struct
from collections.abc import Mapping, Sequence
from pathlib import Path

__all__ = ["ULOG_MAGIC", "flattened_fields", "write_ulog"]

#: The file header's magic bytes, then version 1.
ULOG_MAGIC = b"ULog\x01\x12\x35"
_VERSION = 1

_CODES = {"int8_t": "b", "uint8_t": "B", "int16_t": "h", "uint16_t": "H", "int32_t": "i",
          "uint32_t": "I", "int64_t": "q", "uint64_t": "Q", "float": "f", "double": "d",
          "bool": "?", "char": "B"}  # char as its byte value

#: Topic rows: flattened field name → value.
Row = Mapping[str, float]


def _message(kind: str, payload: bytes) -> bytes:
    """One ULog message: uint16 payload size, uint8 type, payload."""
    return struct.pack("<HB", len(payload), ord(kind)) + payload


def flattened_fields(name: str, formats: Mapping[str, str],
                     prefix: str = "") -> list[tuple[str, str]]:
    """The flattened (field name, struct code) of a format, nested types expanded.

    Parameters
    ----------
    name : str
        The type whose fields to list.
    formats : mapping of str to str
        Every type name → its fields, ``"type name;"`` items.
    prefix : str
        Prepended to every field name (used for nested types).

    Returns
    -------
    list of (str, str)
        Field names as pyulog reports them (arrays as ``f[i]``, nested as ``a[i].f``)
        and their `struct` codes, in payload order.
    """
    out = []
    for item in filter(None, formats[name].split(";")):
        kind, field = item.strip().split(" ")
        size = int(kind[kind.index("[") + 1:-1]) if "[" in kind else 0
        kind = kind.split("[")[0]
        names = [f"{field}[{i}]" for i in range(size)] if size else [field]
        for n in names:
            if kind in _CODES:
                out.append((prefix + n, _CODES[kind]))
            else:
                out += flattened_fields(kind, formats, f"{prefix}{n}.")
    return out


def _info(key: str, value: str) -> bytes:
    """An ``I`` message with a string value."""
    encoded = value.encode()
    field = f"char[{len(encoded)}] {key}".encode()
    return _message("I", struct.pack("<B", len(field)) + field + encoded)


def write_ulog(path: Path, formats: Mapping[str, str],
               topics: Mapping[str | tuple[str, int], Sequence[Row]],
               info: Mapping[str, str] | None = None, start_us: int = 0) -> None:
    """Write a ULog file.

    Parameters
    ----------
    path : Path
        The ``.ulg`` file to write (replaced if present).
    formats : mapping of str to str
        Every type name (logged or nested) → its fields, ``"uint64_t timestamp;..."``.
    topics : mapping of str or (str, int) to sequence of mapping
        Logged topics: type name, or (type name, multi_id) for an instance other than 0,
        → rows of flattened field values (missing fields are 0). Rows are written in the
        given order, topic after topic: pyulog needs no global time order, and tests of
        out-of-order timestamps need them kept.
    info : mapping of str to str, optional
        ``I`` messages, e.g. ``{"sys_name": "PX4", "ver_sw": "v1.15.0"}``.
    start_us : int
        The header's timestamp, µs.

    Raises
    ------
    KeyError
        A topic, or a nested type, without a format.
    struct.error
        A value that does not fit its field type.
    """
    out = bytearray(ULOG_MAGIC + bytes([_VERSION]) + struct.pack("<Q", start_us))
    # Flag bits: no compatible or incompatible flags, no appended data offsets.
    out += _message("B", bytes(16) + struct.pack("<3Q", 0, 0, 0))
    for key, value in (info or {}).items():
        out += _info(key, value)
    for name, fields in formats.items():
        out += _message("F", f"{name}:{fields}".encode())
    for msg_id, (key, rows) in enumerate(topics.items()):
        name, multi_id = (key, 0) if isinstance(key, str) else key
        out += _message("A", struct.pack("<BH", multi_id, msg_id) + name.encode())
        fields = flattened_fields(name, formats)
        layout = struct.Struct("<H" + "".join(code for _, code in fields))
        for row in rows:
            out += _message("D", layout.pack(msg_id, *(row.get(n, 0) for n, _ in fields)))
    Path(path).write_bytes(bytes(out))
