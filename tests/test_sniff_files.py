"""sniff --from-file reads every capture format pdrive writes (issue 27, "Interchange"): a pcap, a
pcapng or a ProfiTrace .ptd (by extension, dp/capfile.py) decodes to the same telegrams as the raw
octets they came from -- the real ET200S start-up of pyprofibus #26, converted by `pdrive convert`."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from test_exit_codes import pdrive

ROOT = Path(__file__).resolve().parent.parent
RAW = ROOT.parent / "shared" / "testdata" / "external" / "pyprofibus26-et200s-startup.raw"

pytestmark = pytest.mark.skipif(not RAW.is_file(), reason="../shared/testdata/external is not there")


def _frames(capsys, monkeypatch, path) -> list[dict]:
    code, out, err = pdrive(capsys, monkeypatch, "sniff", "--from-file", str(path), "--json")
    assert code == 0, err
    return [json.loads(line) for line in out.splitlines()]


def _words(frames: list[dict]) -> list[tuple]:
    """Each telegram without its time (a raw file has none of its own)."""
    return [tuple(sorted((k, json.dumps(v)) for k, v in f.items() if k != "t_s")) for f in frames]


@pytest.mark.parametrize("ext", [".pcap", ".pcapng", ".ptd"])
def test_a_converted_capture_decodes_as_the_raw_one(ext, tmp_path, capsys, monkeypatch):
    out = tmp_path / f"et200s{ext}"
    code, _, err = pdrive(capsys, monkeypatch, "convert", str(RAW), str(out))
    assert code == 0, err
    raw_frames = _frames(capsys, monkeypatch, RAW)
    # the #26 start-up: 15 telegrams, every FCS good (docs: ../shared/testdata/external)
    assert len(raw_frames) == 15 and all(f["event"] == "frame" for f in raw_frames)
    assert _words(_frames(capsys, monkeypatch, out)) == _words(raw_frames)


def test_a_pcap_written_by_sniff_reads_back(tmp_path, capsys, monkeypatch):
    pcap = tmp_path / "back.pcap"
    code, _, err = pdrive(capsys, monkeypatch, "sniff", "--from-file", str(RAW), "--pcap", str(pcap))
    assert code == 0, err
    assert _words(_frames(capsys, monkeypatch, pcap)) == _words(_frames(capsys, monkeypatch, RAW))


def test_a_file_that_is_not_its_extension_is_one_line(tmp_path, capsys, monkeypatch):
    bad = tmp_path / "x.pcap"
    bad.write_bytes(b"not a pcap at all")
    code, out, err = pdrive(capsys, monkeypatch, "sniff", "--from-file", str(bad))
    assert code == 2 and out == ""
    (line,) = err.strip().splitlines()
    assert line.startswith(f"pdrive: {bad}") and "Traceback" not in err
