"""Writing ArduPilot DataFlash logs (``.bin``): FMT messages, then data messages.

A DataFlash log is a stream of messages, each ``0xA3 0x95``, a one-byte type id and the
packed fields (little-endian, no padding). The log describes itself: an ``FMT`` message
(type 128) gives each other type's id, length, name, format characters and column names,
as ArduPilot's ``AP_Logger`` writes them (``libraries/AP_Logger/LogStructure.h``).
pymavlink's `DFFormat` turns format characters into the struct layout, so this writer
packs exactly what pymavlink's ``DFReader`` unpacks; pymavlink itself has no log writer.

Values are passed as stored: the scaled format characters (``c``/``C`` int16/uint16 × 100,
``e``/``E`` int32/uint32 × 100, ``L`` latitude/longitude × 1e7) take the scaled integer,
and the text characters (``n``, ``N``, ``Z``: char[4], char[16], char[64]) take bytes.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

__all__ = ["FMT_TYPE", "HEADER", "DataFlashFormat", "write_dataflash"]

#: The two bytes that start every message.
HEADER = bytes([0xA3, 0x95])
#: Type id of the FMT message, fixed by the format.
FMT_TYPE = 0x80
_FMT_FORMAT = "BBnNZ"
_FMT_COLUMNS = "Type,Length,Name,Format,Columns"

#: One message type: (type id, format characters, comma-separated column names).
DataFlashFormat = tuple[int, str, str]


def write_dataflash(path: Path, formats: Mapping[str, DataFlashFormat],
                    rows: Iterable[tuple[str, tuple[Any, ...]]]) -> None:
    """Write a DataFlash log: an FMT message for each type, then the data messages.

    Parameters
    ----------
    path : Path
        The ``.bin`` file to write (replaced if present).
    formats : mapping of str to (int, str, str)
        Message name (at most 4 characters) → (type id, not 128; format characters, e.g.
        ``"QBffff"``; column names, e.g. ``"TimeUS,C,Q1,Q2,Q3,Q4"``).
    rows : iterable of (str, tuple)
        Data messages in file order: (message name, one value per column, as stored).

    Raises
    ------
    ValueError
        A type id used twice or reserved for FMT, a name longer than 4 characters, or a
        column count that does not match the format.
    KeyError
        A row of a message name not in ``formats``.
    struct.error
        A value that does not fit its format character.
    """
    from pymavlink.DFReader import DFFormat

    ids = [tid for tid, _, _ in formats.values()]
    if len(set(ids)) != len(ids) or FMT_TYPE in ids:
        raise ValueError(f"DataFlash type ids must be distinct and not {FMT_TYPE}: {ids}")
    fmt_fmt = DFFormat(FMT_TYPE, "FMT", 89, _FMT_FORMAT, _FMT_COLUMNS)
    parsed: dict[str, Any] = {}
    for name, (tid, fmt, columns) in formats.items():
        if len(name) > 4 or len(fmt) != len(columns.split(",")):
            raise ValueError(f"DataFlash message {name!r}: a name of at most 4 characters "
                             f"and one column per format character, got {fmt!r}, {columns!r}")
        parsed[name] = DFFormat(tid, name, 0, fmt, columns)

    def message(f: Any, values: Iterable[Any]) -> bytes:
        return HEADER + bytes([f.type]) + struct.pack(f.msg_struct, *values)

    out = bytearray(message(fmt_fmt, (FMT_TYPE, 89, b"FMT", _FMT_FORMAT.encode(),
                                      _FMT_COLUMNS.encode())))
    for name, f in parsed.items():
        length = len(HEADER) + 1 + struct.calcsize(f.msg_struct)
        out += message(fmt_fmt, (f.type, length, name.encode(), f.format.encode(),
                                 ",".join(f.columns).encode()))
    for name, values in rows:
        out += message(parsed[name], values)
    Path(path).write_bytes(bytes(out))
