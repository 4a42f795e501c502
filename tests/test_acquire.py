"""Tests of aacmm_pin.acquire without devices: line formats, nest, pairing, writer, CLI parsers."""

from __future__ import annotations

import argparse
import json
import math
import queue
import re
import threading
from pathlib import Path

import numpy as np
import pytest

from aacmm_pin.acquire import protocols as pr
from aacmm_pin.acquire.faults import AcquisitionError, LineError, PortCounts
from aacmm_pin.acquire.nest import Nest, read_nest
from aacmm_pin.acquire.pairing import Pairer
from aacmm_pin.acquire.session import AcquisitionConfig
from aacmm_pin.acquire.writer import SpatWriter, write_zero
from aacmm_pin.cli.acquisition import add_parsers
from aacmm_pin.cli.iso10360 import add_parsers as add_iso10360
from aacmm_pin.data.campaign import read_campaign
from aacmm_pin.errors import FileFormatError, StaleOutputWarning

Q_DEG = [-35.063444, 78.282159, 171.07413, 35.139578, -135.639175, -78.001445, 128.347322]


def kind_of(call) -> str:
    with pytest.raises(LineError) as info:
        call()
    return info.value.kind


def test_arm_line_round_trip():
    """A formatted arm line parses back to its counter and readouts (deg -> rad)."""
    line = pr.format_arm_line(17, Q_DEG)
    counter, q = pr.parse_arm_line(line, 7)
    assert counter == 17
    np.testing.assert_allclose(np.degrees(q), Q_DEG, rtol=0, atol=1e-9)
    assert line.endswith(b"\r\n") and line.startswith(b"$A,17,")


def test_documented_example_line_is_valid():
    """The example line of the protocols docstring carries the right checksum."""
    example = re.search(rb"\$A,17,[^\s]*", (pr.__doc__ or "").encode())
    assert example is not None
    assert pr.parse_arm_line(example[0], 7)[0] == 17


def test_checksum_is_xor_of_body():
    """The checksum is the XOR of the bytes between '$' and '*' (hand-computed on 'A,1')."""
    assert pr.nmea_checksum(b"A,1") == ord("A") ^ ord(",") ^ ord("1") == 0x5C
    assert pr.format_arm_line(1, []) == b"$A,1,*70\r\n"  # 'A,1,' -> 0x5C ^ 0x2C


@pytest.mark.parametrize(("line", "kind"), [
    (b"$A,17,1.0,2.0,3.0*00", "checksum"),
    (b"$A,17,1.0,2.0*", "garbled"),
    (b"A,17,1.0,2.0,3.0", "garbled"),
    (b"?#%&noise", "garbled"),
    (b"$A,17,1.0,2.0,3.0,4.0*XX", "garbled"),
])
def test_arm_line_faults(line, kind):
    """Bad arm lines are classified: checksum mismatch vs garbled framing."""
    assert kind_of(lambda: pr.parse_arm_line(line, 3)) == kind


@pytest.mark.parametrize(("angles", "kind"), [
    (["1.0", "2.0"], "garbled"),  # too few
    (["1.0", "2.0", "nan"], "garbled"),  # not a decimal number
    (["1.0", "2.0", "1e3"], "garbled"),
    (["1.0", "2.0", "800.0"], "out_of_range"),  # beyond +-720 deg
])
def test_arm_line_bad_fields_with_good_checksum(angles, kind):
    """A line with a good checksum but bad fields is garbled or out of range, never data."""
    body = ("A,5," + ",".join(angles)).encode()
    line = b"$" + body + b"*%02X" % pr.nmea_checksum(body)
    assert kind_of(lambda: pr.parse_arm_line(line, 3)) == kind


def test_csv_arm_format():
    """The csv arm format is q1..qn in degrees with no counter."""
    counter, q = pr.parse_arm_line(b"10,-20.5,30\r", 3, fmt="csv")
    assert counter is None
    np.testing.assert_allclose(q, np.radians([10, -20.5, 30]))
    assert kind_of(lambda: pr.parse_arm_line(b"10,x,30", 3, fmt="csv")) == "garbled"


def test_heidenhain_lines():
    """Heidenhain-style replies give mm -> m; noise and out-of-range values are faults."""
    assert pr.parse_heidenhain(b"+   0.0123 \r") == pytest.approx(1.23e-5, abs=1e-15)
    assert pr.parse_heidenhain(b"-   0.5000") == pytest.approx(-5e-4, abs=1e-15)
    assert pr.parse_heidenhain(pr.format_heidenhain(-0.0042)) == pytest.approx(-4.2e-6, abs=1e-15)
    assert kind_of(lambda: pr.parse_heidenhain(b"ERROR")) == "garbled"
    assert kind_of(lambda: pr.parse_heidenhain(b"+ 0.01x")) == "garbled"
    assert kind_of(lambda: pr.parse_heidenhain(b"+   9.9999 ", 1e-3)) == "out_of_range"


def test_mitutoyo_lines():
    """Mitutoyo-style lines give (channel, m); noise and out-of-range values are faults."""
    assert pr.parse_mitutoyo(b"01A+0000.123") == (1, pytest.approx(1.23e-4, abs=1e-15))
    assert pr.format_mitutoyo(1, 0.123, 3) == b"01A+0000.123\r\n"
    assert pr.parse_mitutoyo(pr.format_mitutoyo(3, -0.0123)) == (3, pytest.approx(-1.23e-5))
    assert kind_of(lambda: pr.parse_mitutoyo(b"91")) == "garbled"
    assert kind_of(lambda: pr.parse_mitutoyo(b"02A+0002.000", 1e-3)) == "out_of_range"


def test_gauge_specs():
    """FORMAT[:CHANNEL]=PORT is parsed; a wrong spec names what is valid."""
    assert pr.parse_gauge_spec("heidenhain:2=/dev/ttyUSB2") == pr.GaugeSpec(
        "heidenhain", 2, "/dev/ttyUSB2")
    assert pr.parse_gauge_spec("heidenhain=/dev/x", default_channel=3).channel == 3
    assert pr.parse_gauge_spec("mitutoyo=loop://").channel is None
    assert str(pr.parse_gauge_spec("heidenhain:1=/dev/a")) == "heidenhain:1=/dev/a"
    for bad, why in [("keyence:1=/dev/a", "choose from"), ("heidenhain:4=/dev/a", "1, 2 or 3"),
                     ("heidenhain=/dev/a", "give its channel"), ("/dev/a", "FORMAT")]:
        with pytest.raises(ValueError, match=why):
            pr.parse_gauge_spec(bad)


def test_config_needs_channels_1_2_3():
    """An acquisition needs gauge channels 1, 2 and 3 once each (or a multi-channel port)."""
    spec = pr.GaugeSpec
    AcquisitionConfig(Path("c"), 1, "a", (spec("mitutoyo", None, "b"),))
    with pytest.raises(ValueError, match="channels 1, 2 and 3"):
        AcquisitionConfig(Path("c"), 1, "a", (spec("heidenhain", 1, "b"), spec("heidenhain", 1, "c"),
                                              spec("heidenhain", 3, "d")))


def test_nest_orthogonal_and_skewed():
    """Readings are the displacement projected on the sensor directions; the nest inverts them."""
    d = np.array([1e-6, 2e-6, 3e-6])
    np.testing.assert_allclose(Nest().displacement(d), d)
    skewed = Nest(np.array([[2.0, 0, 0], [0.6, 0.8, 0], [0, 0, 1]]))  # first row normalised
    readings = np.array([1e-6, 0.6e-6 + 1.6e-6, 3e-6])  # by hand: u_k . d
    np.testing.assert_allclose(skewed.readings(d), readings, rtol=1e-12)
    np.testing.assert_allclose(skewed.displacement(readings), d, rtol=1e-12)
    np.testing.assert_allclose(skewed.displacement(np.tile(readings, (4, 1))), np.tile(d, (4, 1)))


def test_read_nest(tmp_path):
    """A nest file is read; bad JSON, shapes and coplanar directions are reported with the file."""
    good = tmp_path / "nest.json"
    good.write_text(json.dumps({"directions": [[0, 0, 1], [1, 0, 0], [0, 1, 0]]}))
    np.testing.assert_allclose(read_nest(good).displacement([1, 2, 3]), [2, 3, 1])
    for text, why in [("{", "Expecting"), ('{"directions": [[1, 0, 0]]}', "three finite"),
                      ('{"directions": [[1, 0, 0], [0, 1, 0], [1, 1, 0]]}', "coplanar"),
                      ('{"directions": [[1, 0, 0], [0, 0, 0], [0, 0, 1]]}', "vector 2 is zero")]:
        good.write_text(text)
        with pytest.raises(FileFormatError, match=why) as info:
            read_nest(good)
        assert str(good) in str(info.value)


def test_pairer_takes_nearest_reading_within_skew():
    """Each arm sample gets, per channel, the reading nearest in time if within max_skew."""
    pairer = Pairer((1, 2, 3), max_skew=0.01, latency=0.0)
    for t, v in [(0.000, 1.0), (0.004, 2.0), (0.010, 3.0)]:
        for c in (1, 2, 3):
            pairer.add_gauge(c, t, v * c)
    pairer.add_arm(0.003, [0.1])  # nearest: 0.004
    pairer.add_arm(0.006, [0.2])  # nearest: 0.004 (0.002 away, vs 0.004)
    pairer.add_arm(0.008, [0.3])  # nearest: 0.010
    assert pairer.pop(now=0.012) == []  # not ready: a reading up to t + skew may still come
    pairs = pairer.pop(now=0.030)
    assert [p.readings for p in pairs] == [(2.0, 4.0, 6.0), (2.0, 4.0, 6.0), (3.0, 6.0, 9.0)]
    assert [p.q for p in pairs] == [[0.1], [0.2], [0.3]] and pairer.unpaired == 0


def test_pairer_drops_samples_without_a_reading():
    """An arm sample lacking a reading within max_skew on a channel is counted, not paired."""
    pairer = Pairer((1, 2, 3), max_skew=0.005, latency=0.0)
    for c in (1, 2):
        pairer.add_gauge(c, 0.0, 1.0)
    pairer.add_gauge(3, 0.02, 1.0)  # 20 ms late
    pairer.add_arm(0.001, [0.0])
    assert pairer.pop() == []
    assert pairer.unpaired == 1 and pairer.missing == {1: 0, 2: 0, 3: 1}


def test_writer_appends_crash_safe_rows(tmp_path):
    """Rows are on disk after each write (before close) and the folder is a valid campaign."""
    folder = tmp_path / "camp"
    q = np.radians(Q_DEG)
    writer = SpatWriter(folder, 1, zero=np.array([0.1, 0.2, 0.3]))
    assert not (folder / "spat.csv").exists()  # nothing written before the first row
    for k in range(3):
        writer.write(1000.0 + k, q + k * 0.1, np.array([1e-6, -2e-6, 3e-6]))
        lines = (folder / "spat.csv").read_text().splitlines()
        assert len(lines) == k + 2  # header + rows so far, without closing
    campaign = read_campaign(folder)  # readable while the writer is still open
    writer.close()
    assert campaign.spat is not None
    np.testing.assert_allclose(campaign.spat.q[0], q, atol=1e-11)
    np.testing.assert_allclose(campaign.spat.displacement[2], [1e-6, -2e-6, 3e-6], atol=1e-15)
    np.testing.assert_allclose(campaign.spat.t, [1000, 1001, 1002])
    np.testing.assert_allclose(campaign.locations[1], [0.1, 0.2, 0.3])


def test_writer_appends_second_location_and_repairs_torn_line(tmp_path):
    """A second run appends its location; a torn last line of a killed run is removed first."""
    folder = tmp_path / "camp"
    with SpatWriter(folder, 1, zero=np.zeros(3)) as w:
        for k in range(3):
            w.write(float(k), np.zeros(7) + k * 0.01, np.zeros(3))
    with (folder / "spat.csv").open("a") as f:
        f.write("1,0.5,0.5")  # a line cut by a crash
    w2 = SpatWriter(folder, 2, zero=np.array([0.0, 0.1, 0.0]))
    assert (w2.rows_before, w2.location_rows_before, w2.repaired_bytes) == (3, 0, 9)
    for k in range(3):
        w2.write(10.0 + k, np.zeros(7) - k * 0.01, np.ones(3) * 1e-6)
    w2.close()
    campaign = read_campaign(folder)
    assert campaign.spat is not None
    assert campaign.spat.location.tolist() == [1, 1, 1, 2, 2, 2]
    assert sorted(campaign.locations) == [1, 2]


def test_writer_refuses_other_columns_and_other_zero(tmp_path):
    """spat.csv with other columns, or another zero for the location, stop the run before writing."""
    folder = tmp_path / "camp"
    folder.mkdir()
    (folder / "spat.csv").write_text("location,q1_deg,dx_mm,dy_mm,dz_mm\n1,0,0,0,0\n")
    with pytest.raises(AcquisitionError, match="another campaign folder"):
        SpatWriter(folder, 1)
    (folder / "spat.csv").unlink()
    write_zero(folder, 1, np.array([0.1, 0.0, 0.0]))
    with pytest.raises(AcquisitionError, match="leave out --zero"):
        SpatWriter(folder, 1, zero=np.array([0.2, 0.0, 0.0]))
    assert "already has" in SpatWriter(folder, 1, zero=np.array([0.1, 0, 0])).locations_message
    message = SpatWriter(folder, 3).locations_message
    assert "no zero position for location 3" in message and "3,<x_mm>" in message


def test_zero_positions_go_through_the_package_temporaries(tmp_path):
    """locations.csv is replaced through ``.locations.csv.<pid>.*.tmp``; a killed run's is removed."""
    import subprocess
    import sys

    dead = int(subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                              capture_output=True, text=True, check=True).stdout)
    folder = tmp_path / "camp"
    folder.mkdir()
    leftover = folder / f".locations.csv.{dead}.abcd1234.tmp"
    leftover.write_text("location,x_mm\n")
    with pytest.warns(StaleOutputWarning, match="leftover of killed runs"):
        write_zero(folder, 2, np.array([0.1, 0.2, 0.3]))
    write_zero(folder, 1, np.array([0.0, 0.0, 0.001]))
    assert sorted(p.name for p in folder.iterdir()) == ["locations.csv"]
    assert (folder / "locations.csv").read_text() == (
        "location,x_mm,y_mm,z_mm\n1,0.000000000,0.000000000,1.000000000\n"
        "2,100.000000000,200.000000000,300.000000000\n")


def test_port_counts():
    """Fault counts add up by kind."""
    counts = PortCounts()
    counts.add("garbled")
    counts.add("checksum", 2)
    counts.lines += 5
    assert counts.faults == 3 and counts.to_dict()["checksum"] == 2


def test_parsers_set_handlers():
    """The CLI's add_parsers add acquire, fake-devices and iso10360 subcommands, each with a handler."""
    parser = argparse.ArgumentParser()
    subparsers = parser.add_subparsers(dest="command", required=True)
    add_parsers(subparsers)
    add_iso10360(subparsers)
    args = parser.parse_args(["acquire", "camp", "--arm-port", "/dev/a", "--gauge",
                              "mitutoyo=/dev/b", "--location", "2", "--zero", "1,2,-3.5",
                              "--heidenhain-request", r"\x05"])
    assert args.zero == [1.0, 2.0, -3.5] and args.heidenhain_request == b"\x05"
    assert callable(args.handler)
    for argv in (["fake-devices"], ["iso10360", "spat", "c"], ["iso10360", "euni", "c"],
                 ["iso10360", "sphere", "p.csv", "--diameter-mm", "25"],
                 ["iso10360", "ldia", "p.csv"]):
        assert callable(parser.parse_args(argv).handler)
    with pytest.raises(SystemExit):
        parser.parse_args(["acquire", "camp", "--arm-port", "a", "--gauge", "x", "--location",
                           "1", "--zero", "1,2"])


def test_angles_beyond_campaign_limit_are_faults():
    """The arm's angle limit matches the campaign reader's (+-720 deg)."""
    from aacmm_pin.data.campaign import MAX_ANGLE_DEG

    assert pr.MAX_ANGLE_DEG == MAX_ANGLE_DEG
    assert pr.parse_arm_line(pr.format_arm_line(1, [720.0]), 1)[1] == [math.radians(720.0)]


def test_missing_port_stops_before_writing(tmp_path):
    """A port that cannot be opened raises AcquisitionError naming it, and nothing is written."""
    from aacmm_pin.acquire.session import acquire

    config = AcquisitionConfig(tmp_path, 1, "/dev/aacmm-pin-no-such-port",
                               (pr.GaugeSpec("mitutoyo", None, "/dev/aacmm-pin-no-such-gauge"),),
                               zero=np.zeros(3), seconds=1.0)
    with pytest.raises(AcquisitionError, match="aacmm-pin-no-such-port"):
        acquire(config)
    assert list(tmp_path.iterdir()) == []
    parser = argparse.ArgumentParser()
    add_parsers(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["acquire", str(tmp_path), "--arm-port", "x", "--gauge",
                              "heidenhain:1=y", "--location", "1"])
    assert args.handler(args) == 2  # only channel 1: refused before opening anything


def test_pairer_leaves_samples_of_unknown_age_unpaired():
    """A reading whose arrival is uncertain beyond max_skew (a reader's backlog) pairs nothing."""
    pairer = Pairer((1,), max_skew=0.01, latency=0.0)
    pairer.add_gauge(1, 0.000, 1.0)
    pairer.add_arm(0.002, [0.1])  # 2 ms away, known to 1 ms: paired
    pairer.add_arm(0.004, [0.2], u=0.1)  # read from a backlog: anywhere within 0.1 s
    pairer.add_gauge(1, 0.010, 2.0, u=0.009)
    pairer.add_arm(0.011, [0.3])  # 1 ms from a reading known to 9 ms only: 10 ms
    pairer.add_arm(0.012, [0.4])  # 2 + 9 > 10 ms: unpaired
    pairs = pairer.pop(now=1.0)
    assert [p.q for p in pairs] == [[0.1], [0.3]] and pairer.unpaired == 2


def posture_stream(pairer: Pairer, jump: float, arm_delay: float = 0.0, gauge_delay: float = 0.0,
                   end: float = 0.1) -> None:
    """Arm samples and readings every ms, posture 0 before ``jump`` s and posture 1 after.

    The arm reports q = posture, the gauges 1e-5 * (posture + 1) m; each device's values arrive
    ``*_delay`` s late, known within +- 0.5 ms.
    """
    for k in range(int(end * 1000)):
        t = k / 1000
        posture = float(t >= jump)
        pairer.add_arm(t + arm_delay, [posture], u=0.0005)
        for c in (1, 2, 3):
            pairer.add_gauge(c, t + gauge_delay, 1e-5 * (posture + 1), u=0.0005)


@pytest.mark.parametrize("arm_delay, gauge_delay", [(0.0, 0.0), (0.0025, 0.0), (0.0, 0.0025)])
def test_pairer_never_pairs_across_a_posture_change(arm_delay, gauge_delay):
    """A jump of posture: no pair mixes the readouts of one posture with readings of the other.

    Nearest in time pairs across the jump when one device's values come late (a late arm: its
    first samples of the new posture with readings of the old); the pairs near the jump are
    dropped as moving and counted, the others are all made.
    """
    for steady in (True, False):
        pairer = Pairer((1, 2, 3), max_skew=0.01, latency=0.0, steady_rad=0.01 if steady else None,
                        steady_m=1e-7 if steady else None)
        posture_stream(pairer, jump=0.0505, arm_delay=arm_delay, gauge_delay=gauge_delay)
        pairs = pairer.pop()
        mixed = [p for p in pairs if any(abs(r - 1e-5 * (p.q[0] + 1)) > 1e-12 for r in p.readings)]
        if not steady:
            assert mixed or arm_delay == gauge_delay  # what the check is for
            continue
        assert mixed == [] and pairer.moving > 0
        assert len(pairs) + pairer.moving + pairer.unpaired == 100
        assert pairer.moving <= 8  # only those within the timing uncertainty of the jump
        assert all(p.u <= 0.004 for p in pairs)


def test_pairer_waits_for_a_value_after_the_window():
    """A pair is made only when each stream has a value after its window, or HOLD has passed."""
    from aacmm_pin.acquire.pairing import HOLD

    pairer = Pairer((1,), max_skew=0.01, latency=0.0, steady_rad=0.01, steady_m=1e-7)
    pairer.add_gauge(1, 0.000, 1.0)
    pairer.add_arm(0.001, [0.0])
    assert pairer.pop(now=0.05) == []  # no reading after the sample yet: it may show a change
    pairer.add_gauge(1, 0.002, 2.0)  # it does: the sphere moved within the pair's time
    assert pairer.pop(now=0.06) == [] and pairer.moving == 1
    pairer.add_arm(0.10, [0.0])
    pairer.add_gauge(1, 0.10, 2.0)
    assert pairer.pop(now=0.2) == []  # still waiting
    pairs = pairer.pop(now=0.1 + 0.01 + HOLD + 0.001)  # silent devices: what was seen decides
    assert [p.readings for p in pairs] == [(2.0,)] and pairer.paired == 1


def test_lines_read_at_once_get_times_of_their_own():
    """The n lines of one read are spread over the interval they surely arrived in, in order."""
    from aacmm_pin.acquire.ports import spread_stamp

    stamps = [spread_stamp(1.0, 1.004, k, 4) for k in range(4)]
    np.testing.assert_allclose(stamps, [1.0005, 1.0015, 1.0025, 1.0035])
    assert spread_stamp(2.0, 2.0, 0, 1) == 2.0


def test_pairer_memory_is_bounded():
    """An hour-long stream keeps only the values a later pair can need."""
    pairer = Pairer((1, 2, 3), max_skew=0.01, latency=0.0, steady_rad=0.01, steady_m=1e-7)
    for k in range(20000):
        t = k / 1000
        pairer.add_arm(t, [0.0], u=0.0005)
        for c in (1, 2, 3):
            pairer.add_gauge(c, t, 1.0, u=0.0005)
        if k % 100 == 99:
            pairer.pop(now=t)
    assert max(len(s) for s in (pairer._arm, *pairer._gauge.values())) < 4096 + 200
    assert pairer.paired > 19000 and pairer.moving == 0


def test_a_gauge_dithering_by_its_resolution_is_steady():
    """A 1 um gauge (3 decimals of mm) flicking one count at rest: every sample paired (the
    tolerance of 1 um holds a change of one count, however its text rounds)."""
    from aacmm_pin.acquire.protocols import parse_mitutoyo

    pairer = Pairer((1, 2, 3), 0.01, steady_rad=math.radians(0.5), steady_m=1e-6)
    for i in range(500):
        t = i * 1e-3
        pairer.add_arm(t, [0.1] * 7, 0.0002)
        if i % 5 == 0:
            for c in (1, 2, 3):
                _, value = parse_mitutoyo(f"{c:02d}A+0000.{8 + (i // 5) % 2:03d}".encode())
                pairer.add_gauge(c, t + 0.0001, value, 0.0002)
    pairer.pop()
    assert pairer.moving == 0 and pairer.paired > 480


@pytest.mark.parametrize("early", [False, True])
def test_a_change_in_a_wide_window_is_seen_whenever_pop_runs(early):
    """A sample stamped late in a wide read interval, its reading early: the change between them
    is seen whether or not an earlier pop trimmed the streams (it was not, after one)."""
    pairer = Pairer((1,), 0.01, steady_rad=math.radians(0.5), steady_m=1e-6)
    q = [0.1] * 3
    pairer.add_arm(-0.0005, q, span=(-0.001, 0.0))
    pairer.add_arm(0.0174, q, span=(0.0, 0.018))  # the last of several lines read at once
    pairer.add_arm(0.0185, q, span=(0.018, 0.019))
    pairer.add_gauge(1, 0.00055, 0.0, span=(0.0005, 0.0006))
    pairer.add_gauge(1, 0.00305, 1e-4, span=(0.0030, 0.0031))  # 100 um: the posture changed
    pairer.add_gauge(1, 0.0090, 1e-4, span=(0.0085, 0.0095))
    pairer.add_gauge(1, 0.03005, 1e-4, span=(0.030, 0.0301))
    pairs = pairer.pop(0.0174 + 0.01) if early else []
    pairs += pairer.pop()
    assert [p.t for p in pairs if abs(p.t - 0.0174) < 1e-9] == []


def test_stamps_and_intervals_never_go_back():
    """A read that leaves input waiting shares its start with the next read: the next read's
    stamps still follow the earlier ones, and its interval starts no earlier."""
    from aacmm_pin.acquire.ports import PortConfig, PortReader

    config = PortConfig("g", "none", "gauge", lambda line: (1, float(line)))
    reader = PortReader(config, queue.Queue(), threading.Event(), port=object())
    first, _ = reader._lines(bytearray(), b"".join(b"1\n" for _ in range(10)), 0.010, 0.0)
    second, _ = reader._lines(bytearray(), b"".join(b"2\n" for _ in range(40)), 0.011, 0.0)
    stamps = [t for t, *_ in first + second]
    assert np.all(np.diff(stamps) > 0) and stamps[-1] < 0.011
    assert all(lo >= 0.0 for _, _, lo, _ in second)
