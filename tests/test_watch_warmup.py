"""scan --watch says when a station answered only after unanswered requests (issue 26: warm-up,
Baud_Search), in its table and its JSON Lines (`unanswered_before`, as `scan --json` has it).

Expected values by hand: `sim://?warmup=3:4` makes station 3 miss the first 4 valid telegrams on the
line, to any station (sim/slave.py baud_search). The first scan's quick pass asks 0 and 1 (the master
is 2), then 3: the 3rd telegram, missed; its second pass asks 3 again long after 4 telegrams: the
answer, after exactly 1 unanswered FDL status request (dp/scan.py); every other station answers the
first (0)."""

from __future__ import annotations

import io
import json

from click.testing import CliRunner

from profidrive_cli.bustools.buswatch import BusWatch
from profidrive_cli.cli.main import cli
from profidrive_cli.dp.poller import Master
from profidrive_cli.fdl.timing import BusParams
from profidrive_cli.link import open_link
from test_json_contract import assert_stream

URL = "sim://?stations=3:fuji-g1,6:moeller&warmup=3:4"


def test_the_watched_list_keeps_how_late_each_station_answered_its_first_scan():
    m = Master(open_link(URL, 19200), BusParams.for_baud(19200))
    try:
        w = BusWatch(m, 0, 20)
        w.start()
        for _ in range(3):
            w.step()
        assert {s.address: s.unanswered_before for s in w.view().stations} == {3: 1, 6: 0}
    finally:
        m.link.close()


def test_watch_json_lines_carry_unanswered_before():
    r = CliRunner().invoke(cli, ["scan", "--port", URL, "--to", "20", "--watch", "--duration", "0.6",
                                 "--interval", "0.2", "--json"])
    assert r.exit_code == 0, r.output
    lines = [json.loads(x) for x in r.output.splitlines()]
    assert assert_stream(lines, "scan watch")[-1] == "end"          # docs/json.md, the new key in it
    for line in lines:
        assert {s["station"]: s["unanswered_before"] for s in line["stations"]} == {3: 1, 6: 0}


def test_watch_table_says_the_station_answered_late():
    from rich.console import Console

    from profidrive_cli.cli.scan_watch import table
    m = Master(open_link(URL, 19200), BusParams.for_baud(19200))
    try:
        w = BusWatch(m, 0, 20)
        w.start()
        w.step()
        con = Console(width=400, record=True, file=io.StringIO())
        con.print(table(w.view(), "t", None, colour=False))
        text = con.export_text()
    finally:
        m.link.close()
    rows = {line.split("│")[1].strip(): line for line in text.splitlines() if line.count("│") > 3}
    assert "answered after 1 unanswered request (baud-rate search)" in rows["3"]
    assert "unanswered" not in rows["6"]
