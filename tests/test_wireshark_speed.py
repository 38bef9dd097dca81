"""The Lua dissector's cost (issue 27): no object per octet for the FCS, and without a protocol tree
(tshark's summary lines, Wireshark's packet list) a Data_Exchange area that repeats the station's
previous one is not decoded again. Counted, not timed: a postdissector loaded before pdrive.lua
counts the TvbRange objects (tvb(offset, length)) each packet's dissection creates. The summary
lines without a tree must stay exactly the Info column the full dissection (with a tree) writes.

benchmarks/bench_dissector.py times it (telegrams/s against a saturated 1.5 Mbit/s line).
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from test_wireshark import (CHK_CFG, DX_BAD_FCS, DX_REQ, DX_RES, FDL_STATUS, GC, LUA, SC, SET_PRM,
                            SLAVE_DIAG, TOKEN, _pcap, h, run, tshark)  # noqa: F401 (fixture)

# Counts TvbRange objects (Tvb.__call) per packet; the hook is set at the first packet (the first
# packet's count is not reported). Prints "frame N ranges K" on stderr, or "nohook".
COUNTER = """
local post = Proto("pdrivecount", "pdrive test: TvbRange count")
local cur, hooked = 0, false
function post.dissector(tvb, pinfo, tree)
  if not hooked then
    hooked = true
    local mt = getmetatable(tvb)
    local call = mt and mt.__call
    if type(call) ~= "function" then io.stderr:write("nohook\\n") return end
    mt.__call = function(...) cur = cur + 1 return call(...) end
    return
  end
  io.stderr:write(string.format("frame %d ranges %d\\n", pinfo.number, cur))
  cur = 0
end
register_postdissector(post)
"""


def _counts(exe, tmp_path, pcap, *extra, lua=LUA):
    counter = tmp_path / "count.lua"
    counter.write_text(COUNTER)
    p = subprocess.run([exe, "-n", "-X", f"lua_script:{counter}", "-X", f"lua_script:{lua}", "-r", str(pcap),
                        *extra], capture_output=True, text=True, timeout=120,
                       env={**os.environ, "HOME": str(tmp_path)})
    assert p.returncode == 0, p.stderr
    assert "Lua Error" not in p.stdout + p.stderr, p.stdout + p.stderr
    if "nohook" in p.stderr:
        pytest.skip("this tshark's Tvb has no __call to count")
    out = {}
    for line in p.stderr.splitlines():
        if line.startswith("frame "):
            _, n, _, k = line.split()
            out[int(n)] = int(k)
    return out


def _dx(area: bytes, da=6, sa=2, fc=0x7D) -> bytes:
    body = bytes([da, sa, fc]) + area
    return bytes([0x68, len(body), len(body), 0x68]) + body + bytes([sum(body) & 0xFF, 0x16])


def test_fcs_check_makes_no_object_per_octet(tshark, tmp_path):
    """A Data_Exchange with 240 DU octets (no layout has that length: no area decoding) dissected
    with the full tree (-V): the old FCS loop made one TvbRange per octet (>= 243 for the body); the
    sum over one raw string needs none, so the count stays far below the telegram's length."""
    big = _dx(bytes(range(240)))
    assert len(big) == 4 + 3 + 240 + 2
    counts = _counts(tshark, tmp_path, _pcap(tmp_path / "a.pcap", [DX_REQ, big]), "-V")
    assert counts[2] < 40, counts


def test_a_repeated_area_without_a_tree_is_not_decoded_again(tshark, tmp_path):
    """tshark's summary lines (no -V, no -T fields: no protocol tree): the same PPO1 exchange five
    times. The first of each direction is decoded; every repeat is read from one raw string and its
    summary taken from the station's cache: no TvbRange at all (the old dissector made ~48 each)."""
    frames = [SC] + [DX_REQ, DX_RES] * 5
    counts = _counts(tshark, tmp_path, _pcap(tmp_path / "a.pcap", frames))
    assert counts[2] > 0 and counts[3] > 0                 # decoded once per station and direction
    assert [counts[n] for n in range(4, 12)] == [0] * 8, counts


def test_summary_lines_without_a_tree_are_the_info_column_of_the_full_dissection(tshark, tmp_path):
    """Every kind of telegram the tests know, repeated and changed: the Info column of tshark's
    summary lines (no tree: the fast path and the area cache) is the Info column the full dissection
    writes (-T fields -e _ws.col.Info builds the tree), row by row."""
    dx_req2 = _dx(h("00 00 00 00 00 00 00 00 04 7F 30 00"))       # HSW 0x3000 = 75 %
    token_self = h("DC 02 02")
    frames = [SET_PRM, SLAVE_DIAG, CHK_CFG, DX_REQ, DX_RES, DX_REQ, DX_RES, dx_req2, DX_RES, DX_REQ, GC,
              FDL_STATUS, TOKEN, SC, DX_BAD_FCS, token_self, h("10 02 06 00 08 16"), h("00 11 22"),
              _dx(bytes(5)), _dx(bytes(5))]
    pcap = _pcap(tmp_path / "a.pcap", frames)
    env = {**os.environ, "HOME": str(tmp_path)}
    base = [tshark, "-n", "-X", f"lua_script:{LUA}", "-r", str(pcap)]
    plain = subprocess.run(base + ["-T", "fields", "-e", "frame.number", "-e", "_ws.col.Info"],
                           capture_output=True, text=True, timeout=120, env=env)
    summary = subprocess.run(base + ["-o", "gui.column.format:\"No.\",\"%m\",\"Info\",\"%i\""],
                             capture_output=True, text=True, timeout=120, env=env)
    assert plain.returncode == 0 and summary.returncode == 0, plain.stderr + summary.stderr
    with_tree = [line.split("\t", 1)[1] for line in plain.stdout.splitlines()]
    without = [line.strip().split(" ", 1)[1].strip() for line in summary.stdout.splitlines()]
    assert len(with_tree) == len(frames)
    assert without == with_tree
    assert "STW 0x047F" in with_tree[3] and "HSW 0x3000" in with_tree[7]   # the change is decoded
    assert with_tree[9] == with_tree[3]                                     # and the old value again


def test_the_benchmark_derives_the_line_rate_of_a_saturated_1500k_line():
    """bench_dissector's capture: a cycle of the default plant's five stations is 2990 bit times by
    the reference (11 bits per octet, min TSDR 11 and TID1 37 at 1.5M: §1, §4.1), i.e. 5017
    telegrams/s; the script's own sum over the telegrams it writes gives the same."""
    import importlib.util
    spec = importlib.util.spec_from_file_location(
        "bench_dissector", Path(__file__).resolve().parent.parent / "benchmarks" / "bench_dissector.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    # 4 x PPO1 (21 octets each way) + yaskawa extended1 (41 each way), 48 idle bits per exchange
    assert 4 * (21 + 21) * 11 + (41 + 41) * 11 + 5 * (11 + 37) == 2990
    tele = list(mod.telegrams(1.0))
    bits = sum(len(raw) * 11 + (37 if raw[6] & 0x40 else 11) for _, raw in tele)
    rate = len(tele) / (bits / 1_500_000)
    assert abs(rate - 1_500_000 / 2990 * 10) < 1
