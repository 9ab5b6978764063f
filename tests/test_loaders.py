"""Flight-log loaders: CSV, Parquet, PX4 ULog, ArduPilot DataFlash and the suffix dispatch.

Reference values come from (a) signals the tests write themselves with known closed forms,
(b) an independent struct-level DataFlash decoder written here from the format description
(header A3 95, type byte, FMT type 0x80 with ``BBnNZ`` payload), (c) the raw topic arrays
pyulog returns, and (d) values printed in pymavlink's own ``tests/test.BIN.py3.dumped``
(commit b4c7ca298cfac46aa841994d5d3288143e2fa7e5). The real logs are in tests/data (see
its README for source, commit and license).
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from ilcdob.errors import SignalError
from ilcdob.signals import FlightData
from ilcdob.identification.loaders import (SNAP_RTOL, SUFFIXES, load_csv, load_dataflash, load_flight,
                                           load_parquet, load_ulog)

DATA = Path(__file__).parent / "data"
ULG = DATA / "px4_sample_log_small_filtered.ulg"
BIN = DATA / "ardupilot_pymavlink_test.BIN"


# ----------------------------------------------------------------------------- CSV

def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def test_csv_round_trip_of_to_csv(tmp_path):
    t = 100.0 + 0.01 * np.arange(500)          # clock not starting at 0: 10-digit rounding
    x = np.sin(2 * np.pi * 0.7 * t)
    u = np.cos(3.1 * t) * 2.5
    FlightData(t, {"x": x, "acc": u}, {"x": "m", "acc": "m/s^2"}).to_csv(tmp_path / "f.csv")
    fd = load_csv(tmp_path / "f.csv", {"y": "x", "u": "acc"})
    assert fd.source == str(tmp_path / "f.csv")
    assert fd.units == {"y": "m", "u": "m/s^2"}           # from the '# units:' comment line
    assert fd.metadata["resampled"] is False
    assert len(fd) == 500 and fd.ts == pytest.approx(0.01, rel=1e-9)
    np.testing.assert_allclose(fd.t, t, rtol=0, atol=1e-9)   # writer keeps 10 significant digits
    np.testing.assert_allclose(fd["y"], x, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fd["u"], u, rtol=0, atol=1e-8)


def test_csv_comments_renamed_columns_and_unit_override(tmp_path):
    p = _write(tmp_path / "log.csv", "# logger v2\n#units: stamp=ms, pos=m\n\nstamp, pos ,cmd\n"
               + "".join(f"{10 * k}, {0.5 * k}, {k * k}\n" for k in range(6)) + "# trailer\n")
    fd = load_csv(p, {"y": "pos", "u": "cmd"}, time="stamp", units={"u": "m/s^2"})
    np.testing.assert_allclose(fd.t, 0.01 * np.arange(6), atol=1e-15)   # ms -> s
    np.testing.assert_array_equal(fd["y"], 0.5 * np.arange(6))
    np.testing.assert_array_equal(fd["u"], np.arange(6) ** 2)
    assert fd.units == {"y": "m", "u": "m/s^2"}


def test_csv_jittered_time_is_resampled_exactly_for_a_linear_signal(tmp_path):
    rng = np.random.default_rng(1)
    t = np.cumsum(0.01 + 0.004 * rng.random(300))       # 40 % jitter: not uniform
    rows = "".join(f"{a:.12g},{2.0 * a + 1.0:.12g}\n" for a in t)
    p = _write(tmp_path / "j.csv", "time,x\n" + rows)
    fd = load_csv(p, ["x"])
    assert fd.metadata["resampled"] is True
    np.testing.assert_allclose(np.diff(fd.t), fd.ts, rtol=1e-9)
    np.testing.assert_allclose(fd["x"], 2.0 * fd.t + 1.0, atol=1e-9)   # linear interpolation is exact
    fd2 = load_csv(p, ["x"], ts=0.05)
    assert fd2.ts == pytest.approx(0.05, rel=1e-9)
    np.testing.assert_allclose(fd2["x"], 2.0 * fd2.t + 1.0, atol=1e-9)


def test_csv_small_jitter_is_snapped_not_resampled(tmp_path):
    t = 0.02 * np.arange(50)
    t_j = t + 0.5 * SNAP_RTOL * 0.02 * np.sin(np.arange(50))      # within the snap tolerance
    p = _write(tmp_path / "s.csv", "time,x\n" + "".join(f"{a:.12g},{k}\n" for k, a in enumerate(t_j)))
    fd = load_csv(p, ["x"])
    assert fd.metadata["resampled"] is False
    np.testing.assert_array_equal(fd["x"], np.arange(50))
    np.testing.assert_allclose(fd.t, t, atol=SNAP_RTOL * 0.02)


def test_csv_unix_epoch_clock_is_shifted_to_its_first_stamp(tmp_path):
    t = 1.7e9 + 0.01 * np.arange(300)
    p = _write(tmp_path / "e.csv", "time,x\n" + "".join(f"{a:.3f},{k}\n" for k, a in enumerate(t)))
    fd = load_csv(p, ["x"], start=1.7e9 + 1.0, stop=1.7e9 + 2.0)   # window on the file's clock
    assert fd.metadata["time_origin_s"] == 1.7e9
    assert fd.ts == pytest.approx(0.01, rel=1e-9) and len(fd) == 101
    np.testing.assert_allclose(fd.t, 1.0 + 0.01 * np.arange(101), atol=1e-9)
    np.testing.assert_array_equal(fd["x"], np.arange(100, 201))


def test_csv_start_stop_and_nan_outside_window(tmp_path):
    t = 0.1 * np.arange(100)
    x = t.copy()
    x[:10] = np.nan                                      # estimator not converged yet
    lines = "".join(f"{a:.10g},{b}\n" for a, b in zip(t, x))
    p = _write(tmp_path / "w.csv", "time,x\n" + lines)
    fd = load_csv(p, ["x"], start=2.0, stop=5.0)
    assert fd.t[0] == pytest.approx(2.0) and fd.t[-1] == pytest.approx(5.0) and len(fd) == 31
    np.testing.assert_allclose(fd["x"], fd.t, atol=1e-12)
    with pytest.raises(SignalError, match=r"w\.csv.*signal `x` \(column `x`\).*non-finite value nan at line 2, t = 0 s"):
        load_csv(p, ["x"])
    with pytest.raises(SignalError, match=r"w\.csv.*empty selection"):
        load_csv(p, ["x"], start=50.0, stop=60.0)
    with pytest.raises(SignalError, match=r"`stop` = 1\.0 s is not after `start` = 2\.0 s"):
        load_csv(p, ["x"], start=2.0, stop=1.0)


@pytest.mark.parametrize("text, pattern", [
    ("time,x\n0,1\n0.1,2\n", r"c\.csv: signal `y`: column 'pos' not found; columns present: time, x"),
    ("t,pos\n0,1\n0.1,2\n", r"c\.csv: signal `time`: time column 'time' not found; columns present: t, pos"),
    ("time,pos\n0,1\n0.1,inf\n0.2,3\n", r"c\.csv: signal `y` \(column `pos`\): non-finite value inf at line 3"),
    ("time,pos\n0,1\n0.1,abc\n", r"c\.csv: line 3: column `pos`: non-numeric value 'abc'"),
    ("time,pos\n0,1\n0.1,\n", r"c\.csv: line 3: column `pos`: empty value"),
    ("time,pos\n0,1\n0.1,2,7\n", r"c\.csv: line 3: 3 fields, expected 2"),
    ("time,pos\n0,1\n0.1,2\n0.1,3\n", r"c\.csv: time column `time`: duplicated time stamp 0\.1 s at line 3 and line 4"),
    ("time,pos\n0,1\n0.2,2\n0.1,3\n", r"c\.csv: time column `time`: time stamps not increasing at line 4 \(0\.2 -> 0\.1 s\)"),
    ("# units: time=s\n", r"c\.csv: no header row"),
    ("time,pos\n0,1\n", r"c\.csv: 1 data row\(s\)"),
    ("time,pos,pos\n0,1,1\n1,2,2\n", r"c\.csv: line 1: duplicated column name"),
    ("# units: time=min\ntime,pos\n0,1\n1,2\n", r"c\.csv: column `time`: time unit 'min' not supported"),
])
def test_csv_errors_name_file_and_signal(tmp_path, text, pattern):
    p = _write(tmp_path / "c.csv", text)
    with pytest.raises(SignalError, match=pattern):
        load_csv(p, {"y": "pos"})


def test_csv_argument_errors(tmp_path):
    p = _write(tmp_path / "a.csv", "time,pos\n0,1\n1,2\n")
    with pytest.raises(SignalError, match=r"missing\.csv: file not found"):
        load_csv(tmp_path / "missing.csv", ["pos"])
    with pytest.raises(SignalError, match=r"empty\.csv: the file is empty"):
        load_csv(_write(tmp_path / "empty.csv", ""), ["pos"])
    with pytest.raises(SignalError, match=r"`units`: unknown signal 'pso'; valid: pos, time"):
        load_csv(p, ["pos"], units={"pso": "m"})
    with pytest.raises(SignalError, match=r"`ts`: got -0\.1, expected a sample time > 0"):
        load_csv(p, ["pos"], ts=-0.1)
    with pytest.raises(SignalError, match=r"`columns`: empty"):
        load_csv(p, {})
    with pytest.raises(SignalError, match=r"'time' is reserved"):
        load_csv(p, {"time": "pos"})


# ----------------------------------------------------------------------------- Parquet

def test_parquet_round_trip_with_units_metadata(tmp_path):
    t = 5.0 + 0.004 * np.arange(1000)
    x = np.exp(-0.3 * (t - 5.0))
    fd0 = FlightData(t, {"x": x, "acc": -x}, {"x": "m", "acc": "m/s^2"})
    fd0.to_parquet(tmp_path / "f.parquet")
    fd = load_parquet(tmp_path / "f.parquet", {"y": "x", "u": "acc"}, start=6.0)
    assert fd.units == {"y": "m", "u": "m/s^2"}
    assert fd.t[0] == pytest.approx(6.0, abs=1e-9) and fd.t[-1] == pytest.approx(t[-1], abs=1e-9)
    np.testing.assert_allclose(fd["y"], np.exp(-0.3 * (fd.t - 5.0)), rtol=1e-12)   # binary: exact to rounding
    np.testing.assert_allclose(fd["u"], -fd["y"], rtol=0, atol=0)


def test_parquet_timestamp_time_column_and_errors(tmp_path):
    stamps = np.datetime64("2024-05-01T12:00:00", "ms") + np.arange(20) * np.timedelta64(50, "ms")
    tab = pa.table({"time": pa.array(stamps, type=pa.timestamp("ms")), "x": np.arange(20.0),
                    "label": ["a"] * 20, "gap": pa.array([1.0] * 5 + [None] + [1.0] * 14)})
    p = tmp_path / "ts.parquet"
    pq.write_table(tab, p)
    epoch0 = stamps[0].astype(np.int64) * 1e-3                   # s since 1970
    fd = load_parquet(p, ["x"], start=epoch0 + 0.2)               # start/stop on the file's clock
    assert fd.metadata["time_origin_s"] == epoch0              # t is s after the first stamp
    assert fd.ts == pytest.approx(0.05, rel=1e-12) and len(fd) == 16
    np.testing.assert_allclose(fd.t, 0.05 * np.arange(4, 20), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(fd["x"], np.arange(4.0, 20.0))
    with pytest.raises(SignalError, match=r"ts\.parquet: signal `y`: column 'nope' not found; columns present: "
                                          r"time, x, label, gap"):
        load_parquet(p, {"y": "nope"})
    with pytest.raises(SignalError, match=r"ts\.parquet: column `label`: type string, expected numbers"):
        load_parquet(p, ["label"])
    with pytest.raises(SignalError, match=r"ts\.parquet: column `gap`: 1 missing \(null\) value\(s\), first at row 5"):
        load_parquet(p, ["gap"])
    bad = tmp_path / "bad.parquet"
    bad.write_bytes(b"PAR1 this is not a parquet file at all" * 3)
    with pytest.raises(SignalError, match=r"bad\.parquet: cannot read as Parquet"):
        load_parquet(bad, ["x"])


# ----------------------------------------------------------------------------- ULog

def _raw_ulog(topic: str, field: str, instance: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """pyulog's samples of one field, time in s from the log's ``start_timestamp`` (the loader's clock)."""
    from pyulog import ULog

    log = ULog(str(ULG), [topic])
    d = log.get_dataset(topic, instance)
    # signed: a topic may stamp a sample before start_timestamp (actuator_outputs here, by 3.8 ms)
    return (d.data["timestamp"].astype(np.int64) - log.start_timestamp) * 1e-6, d.data[field].astype(float)


def test_ulog_real_log_matches_raw_topics():
    fields = {"z": "vehicle_local_position.z", "thrust": "vehicle_attitude_setpoint.thrust_body[2]"}
    fd = load_ulog(ULG, fields)
    assert fd.source == str(ULG) and fd.metadata["format"] == "ulog"
    assert fd.units == {"z": "m", "thrust": ""}
    tz, z = _raw_ulog("vehicle_local_position", "z")
    tt, thr = _raw_ulog("vehicle_attitude_setpoint", "thrust_body[2]")
    # pinned from the upstream file (pyulog 1.3.0): 636 position samples starting at 20321827 us, the log at
    # 20309082 us (start_timestamp, kept in the metadata): 0.012745 s into the log
    assert z.size == 636 and tz[0] == pytest.approx(0.012745, abs=1e-12)
    assert fd.metadata["start_timestamp_s"] == pytest.approx(20.309082, abs=1e-12)
    # grid: overlap of both topics, finest median step (the ~100 Hz position topic)
    assert fd.t[0] == pytest.approx(max(tz[0], tt[0]), abs=1e-12)
    assert fd.ts == pytest.approx(np.median(np.diff(tz)), rel=1e-12)
    assert fd.t[-1] <= min(tz[-1], tt[-1]) + 1e-9
    np.testing.assert_allclose(fd["z"], np.interp(fd.t, tz, z), rtol=0, atol=1e-12)
    np.testing.assert_allclose(fd["thrust"], np.interp(fd.t, tt, thr), rtol=0, atol=1e-12)
    assert fd.metadata["info"]["sys_name"] == "PX4"
    assert fd.metadata["original_rates_hz"]["thrust"] == pytest.approx(1 / np.median(np.diff(tt)))


def test_ulog_multi_instance_and_segment():
    fd = load_ulog(ULG, {"o0": "actuator_outputs.output[0]", "o1": "actuator_outputs:1.output[0]"},
                   ts=0.05, start=1.7, stop=4.7)  # s from the log's start
    t0, x0 = _raw_ulog("actuator_outputs", "output[0]", 0)
    t1, x1 = _raw_ulog("actuator_outputs", "output[0]", 1)
    assert not np.allclose(x0[:20], x1[:20])          # the two instances really differ
    # the grid is anchored at start: 1.70, 1.75, ..., 4.70 s
    assert fd.ts == pytest.approx(0.05) and len(fd) == 61
    np.testing.assert_allclose(fd.t, 1.7 + 0.05 * np.arange(61), atol=1e-9)
    np.testing.assert_allclose(fd["o0"], np.interp(fd.t, t0, x0), atol=1e-9)
    np.testing.assert_allclose(fd["o1"], np.interp(fd.t, t1, x1), atol=1e-9)


@pytest.mark.parametrize("spec, pattern", [
    ("vehicle_gps_position.lat", r"topic 'vehicle_gps_position' not in the log; topics with data: actuator_outputs, "
                                 r"actuator_outputs:1, vehicle_attitude_setpoint, vehicle_local_position"),
    ("vehicle_local_position.xx", r"topic 'vehicle_local_position' has no field 'xx'; fields: ref_timestamp, "),
    ("actuator_outputs:2.output[0]", r"topic 'actuator_outputs' has no instance 2; instances logged: \[0, 1\]"),
    ("vehicle_local_position", r"field 'vehicle_local_position' not of the form 'topic\.field'"),
])
def test_ulog_missing_topic_field_instance(spec, pattern):
    with pytest.raises(SignalError, match=r"px4_sample_log_small_filtered\.ulg: signal `y`: " + pattern):
        load_ulog(ULG, {"y": spec})


def test_ulog_corrupt_truncated_and_empty_window(tmp_path):
    bad = tmp_path / "bad.ulg"
    bad.write_bytes(b"\x00" * 4096)
    with pytest.raises(SignalError, match=r"bad\.ulg: cannot read as a PX4 ULog file"):
        load_ulog(bad, {"y": "vehicle_local_position.z"})
    cut = tmp_path / "cut.ulg"
    cut.write_bytes(ULG.read_bytes()[:20000])           # header and definitions only
    with pytest.raises(SignalError, match=r"cut\.ulg: signal `y`: .*no logged data"):
        load_ulog(cut, {"y": "vehicle_local_position.z"})
    with pytest.raises(SignalError, match=r"signal `y` \(vehicle_local_position\.z\): empty selection.*"
                                          r"data span 0\.012745 to 6\.508897 s"):  # to the us: typed back as --start
        load_ulog(ULG, {"y": "vehicle_local_position.z"}, start=100.0, stop=200.0)


# ----------------------------------------------------------------------------- DataFlash

_DF_STRUCT = {"a": ("64s", None), "b": ("b", None), "B": ("B", None), "h": ("h", None), "H": ("H", None),
              "i": ("i", None), "I": ("I", None), "f": ("f", None), "d": ("d", None), "n": ("4s", None),
              "N": ("16s", None), "Z": ("64s", None), "c": ("h", 0.01), "C": ("H", 0.01), "e": ("i", 0.01),
              "E": ("I", 0.01), "L": ("i", 1e-7), "M": ("B", None), "q": ("q", None), "Q": ("Q", None),
              "g": ("e", None)}


def _cstr(b: bytes) -> str:
    return b.split(b"\0")[0].decode("ascii")


def _decode_dataflash(raw: bytes) -> dict[str, list[dict]]:
    """Independent decoder: every message as {column: value}, grouped by message name."""
    fmts = {0x80: ("FMT", "BBnNZ", ["Type", "Length", "Name", "Format", "Columns"], 89)}
    out: dict[str, list[dict]] = {}
    i = 0
    while i + 3 <= len(raw):
        if raw[i] != 0xA3 or raw[i + 1] != 0x95 or raw[i + 2] not in fmts:
            i += 1
            continue
        name, fmt, cols, length = fmts[raw[i + 2]]
        if i + length > len(raw):
            break
        st = struct.Struct("<" + "".join(_DF_STRUCT[c][0] for c in fmt))
        vals = st.unpack_from(raw, i + 3)
        if name == "FMT":
            fmts[vals[0]] = (_cstr(vals[2]), _cstr(vals[3]), _cstr(vals[4]).split(","), vals[1])
        else:
            rec = {}
            for c, v, f in zip(cols, vals, fmt):
                mult = _DF_STRUCT[f][1]
                rec[c] = v * mult if mult is not None else v
            out.setdefault(name, []).append(rec)
        i += length
    return out


def test_dataflash_real_log_matches_independent_decoder():
    ref = _decode_dataflash(BIN.read_bytes())
    # values printed in pymavlink tests/test.BIN.py3.dumped
    assert len(ref["POS"]) == 23 and len(ref["ATT"]) == 24
    assert ref["POS"][0]["TimeUS"] == 81796345 and ref["POS"][0]["Lat"] == pytest.approx(-35.3626298, abs=1e-9)
    assert ref["POS"][-1]["TimeUS"] == 82730515 and ref["ATT"][0]["Roll"] == pytest.approx(-7.18, abs=1e-12)

    fd = load_dataflash(BIN, {"lat": "POS.Lat", "alt": "POS.Alt", "roll": "ATT.Roll"})
    assert fd.source == str(BIN) and fd.metadata["message_counts"] == {"POS": 23, "ATT": 24}
    tp = np.array([r["TimeUS"] for r in ref["POS"]]) * 1e-6
    ta = np.array([r["TimeUS"] for r in ref["ATT"]]) * 1e-6
    assert fd.t[0] == pytest.approx(max(tp[0], ta[0]), abs=1e-12)
    np.testing.assert_allclose(fd["lat"], np.interp(fd.t, tp, [r["Lat"] for r in ref["POS"]]), rtol=0, atol=1e-9)
    np.testing.assert_allclose(fd["alt"], np.interp(fd.t, tp, [r["Alt"] for r in ref["POS"]]), rtol=0, atol=1e-9)
    np.testing.assert_allclose(fd["roll"], np.interp(fd.t, ta, [r["Roll"] for r in ref["ATT"]]), rtol=0, atol=1e-9)

    one = load_dataflash(BIN, {"lat": "POS.Lat"})                # a single type keeps its own first stamp
    assert one.t[0] == 81.796345 and one["lat"][0] == pytest.approx(-35.3626298, abs=1e-9)


@pytest.mark.parametrize("spec, pattern", [
    ("PSCN.PN", r"message type 'PSCN' not in the log; types with data: AETR, AHR2, AOA, ATT, "),
    ("POS.North", r"message type 'POS' has no field 'North'; fields: TimeUS, Lat, Lng, Alt, RelHomeAlt, RelOriginAlt"),
    ("IMU[1].AccX", r"message type 'IMU' has no instance column in this log"),
    ("POS", r"field 'POS' not of the form 'TYPE\.Field'"),
])
def test_dataflash_missing_type_field_instance(spec, pattern):
    with pytest.raises(SignalError, match=r"ardupilot_pymavlink_test\.BIN: signal `y`: " + pattern):
        load_dataflash(BIN, {"y": spec})


# A tiny DataFlash log written from the format description (FMT, UNIT, FMTU, data).
def _fmt(type_id: int, name: str, fmt: str, cols: str) -> bytes:
    length = 3 + struct.calcsize("<" + "".join(_DF_STRUCT[c][0] for c in fmt))
    return bytes([0xA3, 0x95, 0x80]) + struct.pack("<BB4s16s64s", type_id, length, name.encode(), fmt.encode(),
                                                   cols.encode())


def _msg(type_id: int, fmt: str, *vals) -> bytes:
    return bytes([0xA3, 0x95, type_id]) + struct.pack("<" + "".join(_DF_STRUCT[c][0] for c in fmt), *vals)


def _synthetic_log(path: Path, imu_times=None, acc=None, text_field=False) -> Path:
    n = 40
    times = np.arange(n) * 10_000 + 1_000_000 if imu_times is None else np.asarray(imu_times)
    acc = np.sin(0.2 * np.arange(n)) if acc is None else np.asarray(acc)
    b = _fmt(0x80, "FMT", "BBnNZ", "Type,Length,Name,Format,Columns")
    b += _fmt(177, "UNIT", "QbZ", "TimeUS,Id,Label") + _fmt(178, "FMTU", "QBNN", "TimeUS,FmtType,UnitIds,MultIds")
    b += _fmt(200, "IMU", "QBff", "TimeUS,I,AccX,GyrX") + _fmt(201, "MSGX", "QZ", "TimeUS,Text")
    for uid, label in ((ord("s"), "s"), (ord("#"), "instance"), (ord("o"), "m/s/s"), (ord("E"), "rad/s")):
        b += _msg(177, "QbZ", 0, uid, label.encode())
    b += _msg(178, "QBNN", 0, 200, b"s#oE", b"----")
    for k in range(len(times)):
        for inst in (0, 1):                         # instance 1 reads 10 x instance 0
            b += _msg(200, "QBff", int(times[k]) + inst, inst, (1 + 9 * inst) * acc[k], 0.0)
        if text_field:
            b += _msg(201, "QZ", int(times[k]), b"hello")
    path.write_bytes(b)
    return path


def test_dataflash_synthetic_instances_units_and_text_log(tmp_path):
    p = _synthetic_log(tmp_path / "syn.bin")
    acc = np.sin(0.2 * np.arange(40))
    fd = load_dataflash(p, {"a0": "IMU[0].AccX", "a1": "IMU:1.AccX"})
    assert fd.units == {"a0": "m/s/s", "a1": "m/s/s"}          # from UNIT + FMTU
    assert fd.ts == pytest.approx(0.01, rel=1e-9)
    assert fd.t[0] == pytest.approx(1.000001, abs=1e-12)       # instance 1 starts 1 us later
    t0 = 1.0 + 0.01 * np.arange(40)
    np.testing.assert_allclose(fd["a0"], np.interp(fd.t, t0, acc.astype(np.float32)), atol=1e-6)
    np.testing.assert_allclose(fd["a1"], np.interp(fd.t, t0 + 1e-6, (10 * acc).astype(np.float32)), atol=1e-6)
    with pytest.raises(SignalError, match=r"syn\.bin: signal `y`: message type 'IMU' has no instance 3 "
                                          r"\(I values logged: \['0', '1'\]\)"):
        load_dataflash(p, {"y": "IMU[3].AccX"})


@pytest.mark.parametrize("kw, pattern", [
    (dict(imu_times=[1_000_000, 1_010_000, 1_010_000, 1_030_000]), r"signal `y` \(IMU\[0\]\.AccX\): duplicated time stamp 1\.01 s at sample 1 and sample 2"),
    (dict(imu_times=[1_000_000, 1_020_000, 1_010_000, 1_030_000]), r"signal `y` \(IMU\[0\]\.AccX\): time stamps not increasing at sample 2 \(1\.02 -> 1\.01 s\)"),
    (dict(imu_times=[1_000_000, 1_010_000, 1_020_000], acc=[0.0, float("nan"), 1.0]),
     r"signal `y` \(IMU\[0\]\.AccX\): non-finite value nan at t = 1\.01 s"),
])
def test_dataflash_bad_time_stamps_and_values(tmp_path, kw, pattern):
    p = _synthetic_log(tmp_path / "bad.bin", **kw)
    with pytest.raises(SignalError, match=r"bad\.bin: " + pattern):
        load_dataflash(p, {"y": "IMU[0].AccX"})


def test_dataflash_text_field_and_corrupt_files(tmp_path):
    p = _synthetic_log(tmp_path / "txt.bin", text_field=True)
    with pytest.raises(SignalError, match=r"txt\.bin: signal `y`: field MSGX\.Text holds text \('hello'\)"):
        load_dataflash(p, {"y": "MSGX.Text"})
    junk = tmp_path / "junk.bin"
    junk.write_bytes(bytes(range(256)) * 8)
    with pytest.raises(SignalError, match=r"junk\.bin: not an ArduPilot DataFlash log: a binary log starts with "
                                          r"bytes A3 95 80 \(got 00 01 02\)"):
        load_dataflash(junk, {"y": "POS.Lat"})
    only_fmt = tmp_path / "fmt.bin"
    only_fmt.write_bytes(BIN.read_bytes()[:89 * 3])            # three FMT messages, no data
    with pytest.raises(SignalError, match=r"fmt\.bin: no data messages in the DataFlash log"):
        load_dataflash(only_fmt, {"y": "POS.Lat"})


def test_dataflash_text_log(tmp_path):
    lines = ["FMT, 128, 89, FMT, BBnNZ, Type,Length,Name,Format,Columns",
             "FMT, 200, 23, PSCN, Qfff, TimeUS,TPN,PN,DVN"]
    lines += [f"PSCN, {2_000_000 + 20_000 * k}, 0, {0.1 * k:.3f}, 0" for k in range(30)]
    p = tmp_path / "flight.log"
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    fd = load_flight(p, {"y": "PSCN.PN"})
    assert fd.t[0] == pytest.approx(2.0) and fd.ts == pytest.approx(0.02, rel=1e-9) and len(fd) == 30
    np.testing.assert_allclose(fd["y"], 5.0 * (fd.t - 2.0), atol=1e-9)   # PN = 0.1 k, t = 2 + 0.02 k


# ----------------------------------------------------------------------------- dispatch

def test_load_flight_dispatch(tmp_path):
    t = 0.01 * np.arange(200)
    fd0 = FlightData(t, {"x": np.cos(t)}, {"x": "m"})
    fd0.to_csv(tmp_path / "a.CSV")
    fd0.to_parquet(tmp_path / "a.pq")
    for name in ("a.CSV", "a.pq"):
        fd = load_flight(tmp_path / name, {"y": "x"}, stop=1.0)
        assert len(fd) == 101 and fd.units == {"y": "m"}
        np.testing.assert_allclose(fd["y"], np.cos(fd.t), atol=1e-9)
    assert load_flight(ULG, {"z": "vehicle_local_position.z"}).metadata["format"] == "ulog"
    assert load_flight(BIN, {"lat": "POS.Lat"}).metadata["format"] == "dataflash"
    with pytest.raises(SignalError, match=r"a\.txt: unknown file suffix '\.txt'; valid: "
                                          + ", ".join(s.replace(".", r"\.") for s in SUFFIXES)):
        load_flight(tmp_path / "a.txt", {"y": "x"})
    with pytest.raises(SignalError, match=r"`time`: got 'stamp'; a \.ulg log carries its own clock"):
        load_flight(ULG, {"z": "vehicle_local_position.z"}, time="stamp")
    with pytest.raises(SignalError, match=r"unknown keyword argument\(s\) \['tss'\]"):
        load_flight(ULG, {"z": "vehicle_local_position.z"}, tss=0.1)


def test_time_unit_comment_line(tmp_path):
    """``# time: ms`` before the header states the time column's unit, on the fast (pyarrow) and
    the line-by-line path alike (a comment inside the data takes the latter)."""
    rows = "\n".join(f"{20 * k},{np.sin(k / 10):.6f}" for k in range(200))
    (tmp_path / "fast.csv").write_text(f"# time: ms\ntime,x\n{rows}\n")
    (tmp_path / "slow.csv").write_text(f"# time: ms\ntime,x\n{rows}\n# end of log\n")
    for name in ("fast.csv", "slow.csv"):
        fd = load_csv(tmp_path / name, {"x": "x"})
        assert fd.ts == pytest.approx(0.02) and fd.t[-1] == pytest.approx(199 * 0.02), name
