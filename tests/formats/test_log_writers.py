"""The DataFlash and ULog writers: pymavlink's DFReader and pyulog read back what they wrote."""

from __future__ import annotations

import numpy as np
import pytest
from mavsysid.formats.dataflash_writer import write_dataflash
from mavsysid.formats.ulog_writer import flattened_fields, write_ulog

_FORMATS = {
    "MODE": (11, "QMBB", "TimeUS,Mode,ModeNum,Rsn"),
    "XKF1": (181, "QBccCfffffffccce", "TimeUS,C,Roll,Pitch,Yaw,VN,VE,VD,dPD,PN,PE,PD,"
                                      "GX,GY,GZ,OH"),
    "MSG": (91, "QZ", "TimeUS,Message"),
}


def test_dataflash_round_trip_through_dfreader(tmp_path):
    from pymavlink.DFReader import DFReader_binary

    rng = np.random.default_rng(4)
    values = rng.normal(size=(5, 7))
    rows = [("MSG", (1000, b"ArduCopter V4.5.7"))]
    rows += [("XKF1", (2000 + 10 * i, 0, round(v[0] * 100), round(v[1] * 100), 1234, *v,
                       0, 0, 0, 0)) for i, v in enumerate(values)]
    rows.append(("MODE", (5000, 4, 4, 2)))
    path = tmp_path / "a.bin"
    write_dataflash(path, _FORMATS, rows)
    log = DFReader_binary(str(path))
    got = list(iter(lambda: log.recv_match(type=["XKF1", "MODE", "MSG"]), None))
    assert [m.get_type() for m in got] == ["MSG", *["XKF1"] * 5, "MODE"]
    assert got[0].Message == "ArduCopter V4.5.7"
    xkf1 = got[1:6]
    np.testing.assert_allclose([m.TimeUS for m in xkf1], 2000 + 10 * np.arange(5))
    # Scaled characters come back in their unit (c: centi), floats at single precision.
    np.testing.assert_allclose([m.Roll for m in xkf1], np.round(values[:, 0] * 100) / 100)
    np.testing.assert_allclose([m.Yaw for m in xkf1], 12.34)
    np.testing.assert_allclose([[m.VN, m.VE, m.VD, m.dPD, m.PN, m.PE, m.PD] for m in xkf1],
                               values, rtol=1e-6)
    assert (got[6].Mode, got[6].Rsn) == (4, 2)


@pytest.mark.parametrize("formats", [
    {"MODE": (128, "QMBB", "TimeUS,Mode,ModeNum,Rsn")},
    {"MODE": (11, "QMBB", "TimeUS,Mode,ModeNum,Rsn"), "MSG": (11, "QZ", "TimeUS,Message")},
    {"MODE": (11, "QMB", "TimeUS,Mode,ModeNum,Rsn")},
    {"TOOLONG": (12, "Q", "TimeUS")},
])
def test_dataflash_bad_formats_are_refused(tmp_path, formats):
    with pytest.raises(ValueError):
        write_dataflash(tmp_path / "a.bin", formats, [])


_ULOG_FORMATS = {
    "esc_report": "uint64_t timestamp;int32_t esc_rpm;float esc_voltage;",
    "esc_status": "uint64_t timestamp;uint8_t esc_count;esc_report[2] esc;",
    "vehicle_attitude": "uint64_t timestamp;float[4] q;",
}


def test_flattened_fields_expand_arrays_and_nested_types():
    fields = flattened_fields("esc_status", _ULOG_FORMATS)
    assert [name for name, _ in fields] == [
        "timestamp", "esc_count", "esc[0].timestamp", "esc[0].esc_rpm", "esc[0].esc_voltage",
        "esc[1].timestamp", "esc[1].esc_rpm", "esc[1].esc_voltage"]
    assert "".join(code for _, code in fields) == "QBQifQif"


def test_ulog_round_trip_through_pyulog(tmp_path):
    from pyulog import ULog

    rng = np.random.default_rng(5)
    q = rng.normal(size=(6, 4))
    rpm = rng.integers(1000, 20000, size=(4, 2))
    topics = {
        "vehicle_attitude": [{"timestamp": 1000 * (i + 1), **{f"q[{c}]": q[i, c]
                                                              for c in range(4)}}
                             for i in range(6)],
        "esc_status": [{"timestamp": 1500 * (i + 1), "esc_count": 2,
                        **{f"esc[{m}].esc_rpm": int(rpm[i, m]) for m in range(2)}}
                       for i in range(4)],
        ("vehicle_attitude", 1): [{"timestamp": 7, "q[0]": 1.0}],
    }
    path = tmp_path / "a.ulg"
    write_ulog(path, _ULOG_FORMATS, topics, info={"sys_name": "PX4"}, start_us=500)
    ulog = ULog(str(path))
    assert ulog.msg_info_dict["sys_name"] == "PX4"
    assert ulog.start_timestamp == 500
    data = {(d.name, d.multi_id): d.data for d in ulog.data_list}
    np.testing.assert_allclose(np.column_stack([data["vehicle_attitude", 0][f"q[{c}]"]
                                                for c in range(4)]), q, rtol=1e-6)
    np.testing.assert_array_equal(data["vehicle_attitude", 1]["timestamp"], [7])
    esc = data["esc_status", 0]
    np.testing.assert_array_equal(np.column_stack([esc["esc[0].esc_rpm"],
                                                   esc["esc[1].esc_rpm"]]), rpm)
    np.testing.assert_array_equal(esc["esc[1].esc_voltage"], 0.0)  # missing fields are 0
