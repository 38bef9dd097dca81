"""Exact exit codes of `pdrive` (cli/main.py main(), what the shell sees): 2 for bad input, 1 for a
bus or station problem, 0 for success; the error is one line on stderr, nothing on stdout and no
traceback (preamble of docs/commands.md: "Errors are one line: exit 2 for bad input ...").

The click test runner turns every exception into exit code 1, so these run main() itself."""

import pytest

from profidrive_cli.cli.main import main


def pdrive(capsys, monkeypatch, *argv):
    monkeypatch.setenv("PDRIVE_PORT", "")
    monkeypatch.delenv("PDRIVE_STATION", raising=False)
    with pytest.raises(SystemExit) as e:
        main(list(argv))
    out, err = capsys.readouterr()
    return e.value.code, out, err


# (argv, exit code, words of the one-line error)
ERRORS = [
    (["scan"], 2, "no port given"),
    (["diag", "200", "--port", "sim://"], 2, "station address 200 outside 0..125"),
    (["io", "7", "--port", "sim://", "--cfg", "ZZ"], 2, "--cfg: not hex"),
    (["scan", "--port", "sim://", "--baud", "1234"], 2, "not a PROFIBUS-DP baud rate"),
    (["scan", "--port", "sim://?stations=3:nosuch"], 2, "unknown profile 'nosuch'"),
    # parse_baud: a number with no integer (inf, 1e999) is a bad rate like any other, not a crash
    (["scan", "--port", "sim://", "--baud", "inf"], 2, "'inf' is not a PROFIBUS-DP baud rate"),
    (["scan", "--port", "sim://", "--baud", "1e999"], 2, "'1e999' is not a PROFIBUS-DP baud rate"),
    # a station at the master's own address: refused before the port is opened
    (["status", "3", "--port", "sim://", "--master-address", "3"], 2,
     "station 3 is the master's own address (--master-address = 3)"),
    (["diag", "9", "--port", "sim://"], 1, "station 9 does not answer"),
    (["io", "7", "--port", "sim://", "--cfg", "F1"], 1, "configuration fault"),
    (["scan", "--port", "/dev/does-not-exist"], 1, "no such port"),
]


@pytest.mark.parametrize("argv,code,words", ERRORS, ids=[" ".join(a[:2]) + f" -> {c}" for a, c, _ in ERRORS])
def test_errors_have_their_exit_code_and_one_line(capsys, monkeypatch, argv, code, words):
    rc, out, err = pdrive(capsys, monkeypatch, *argv)
    assert rc == code
    assert out == ""
    assert err.startswith("pdrive: ") and words in err
    assert err.count("\n") == 1 and "Traceback" not in err


def test_scan_success_is_0(capsys, monkeypatch):
    rc, out, err = pdrive(capsys, monkeypatch, "scan", "--port", "sim://", "--to", "4")
    assert rc == 0 and "2 station(s)" in out


def test_scan_finding_nothing_is_1(capsys, monkeypatch):
    rc, out, _ = pdrive(capsys, monkeypatch, "scan", "--port", "sim://", "--from", "10", "--to", "20")
    assert rc == 1 and "no station answered" in out


def test_scan_json_finding_nothing_is_1_too(capsys, monkeypatch):
    rc, out, _ = pdrive(capsys, monkeypatch, "scan", "--port", "sim://", "--from", "10", "--to", "20",
                        "--json")
    assert '"stations": []' in out
    assert rc == 1
