"""Random input never escapes as anything but DataFileError (parse) / UsageError (interpretation)."""

from __future__ import annotations

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from profidrive_cli import UsageError
from profidrive_cli.datafile import DataFileError
from profidrive_cli.gsd import build_prm, decode_unit_diag, parse_gsd_bytes, parse_gsd_text

# pieces of real GSD syntax, so that random combinations get past the first lines
PIECES = [
    "#Profibus_DP", "Ident_Number = 0x1234", "Ident_Number = 12a", "Vendor_Name = \"V\"", "Vendor_Name = \"V",
    "Module = \"M\" 0xF3, 0xF1", "Module = \"S\" 0xC0, 0x01", "Module = \"X\" 0x00", "Module = \"N\"",
    "EndModule", "1", "0x10", "Ext_Module_Prm_Data_Len = 3", "Ext_Module_Prm_Data_Len = 999",
    "Ext_User_Prm_Data_Const(0) = 0x01, 0x02", "Ext_User_Prm_Data_Const(236) = 1, 2",
    "Ext_User_Prm_Data_Ref(1) = 1", "Ext_User_Prm_Data_Ref(0) = 2", "Ext_User_Prm_Data_Ref(5) = 3",
    "ExtUserPrmData = 1 \"a\"", "ExtUserPrmData = 2 \"b\"", "ExtUserPrmData = 3", "Bit(3) 1 0-1",
    "BitArea(2-5) 3 1,3,7", "BitArea(5-2) 1 0-1", "Unsigned16 70000 0-65535", "Signed8 -5 -10--1",
    "Unsigned32 1", "Signed32 -1 -1-1", "OctetString 3", "Prm_Text_Ref = 1", "Changeable = 0",
    "EndExtUserPrmData", "PrmText = 1", "Text(0) = \"zero\"", "Text(-3) = \"m\"", "EndPrmText",
    "User_Prm_Data_Len = 4", "User_Prm_Data_Len = 500", "User_Prm_Data = 1, 2, 3", "Max_Module = 1",
    "Modular_Station = 1", "Unit_Diag_Bit(3) = \"u\"", "Unit_Diag_Area = 8-15", "Unit_Diag_Area = 0-40",
    "Value(1) = \"v\"", "Unit_Diag_Area_End", "UnitDiagType = 129", "X_Unit_Diag_Bit(9) = \"x\"",
    "EndUnitDiagType", "SlotDefinition", "Slot(1) = \"s\" 1 1-3", "EndSlotDefinition", "Data_Area_Beg",
    "Data_Area_End", "MaxTsd_12M = 5", "12M_supp = 1", "Slave_Family = 1@x", "; comment", "\\",
    "Foo_Bar(2) = \"q\" 1", "= 5", "(", ")", "\"", ",", "-", "@", "Modul_Offset = 1",
    "ExtUserPrmData = 4 \"[SlotNumber]\"", "Unsigned8 1 1-5", "F_Ext_User_Prm_Data_Ref(0) = 4",
]
SEPS = ["\n", "\r\n", "\r", " \\\n", " ", ";x\n"]

gsd_like = st.lists(st.tuples(st.sampled_from(PIECES), st.sampled_from(SEPS)), max_size=40).map(
    lambda parts: "#Profibus_DP\n" + "".join(p + s for p, s in parts))


# structured files: well-formed blocks with random contents, then optionally one line dropped or mangled
_num = st.one_of(st.integers(-5, 300), st.sampled_from([0, 1, 7, 8, 255, 256, 65535, 65536, 2**32]))
_hex = st.integers(0, 255).map(lambda v: f"0x{v:02X}")
_bit = st.integers(0, 7)
_compact = st.integers(0, 255).filter(lambda v: v & 0x30).map(lambda v: f"0x{v:02X}")
_special = st.sampled_from(["0x00", "0xC0, 0x01, 0x7D", "0x43, 0x00, 0x00, 0x1F, 0xC1", "0x81, 0x07"])
_types = st.sampled_from(["Bit({a})", "BitArea({a}-{b})", "Unsigned8", "Unsigned16", "Unsigned32", "Signed8",
                          "Signed16", "Signed32"])


@st.composite
def ext_user_prm_data(draw, ref):
    a, b = sorted((draw(_bit), draw(_bit)))
    t = draw(_types).format(a=a, b=b)
    default = draw(_num)
    allowed = draw(st.one_of(st.just(""), st.tuples(_num, _num).map(lambda ab: f"{min(ab)}-{max(ab)}"),
                             st.lists(_num, min_size=1, max_size=4).map(lambda v: ",".join(map(str, v)))))
    extra = draw(st.sampled_from(["", "Prm_Text_Ref = 1\n", "Prm_Text_Ref = 9\n", "Changeable = 0\n"]))
    return f'ExtUserPrmData = {ref} "p{ref}"\n{t} {default} {allowed}\n{extra}EndExtUserPrmData\n'


@st.composite
def prm_lines(draw):
    out = []
    for _ in range(draw(st.integers(0, 4))):
        if draw(st.booleans()):
            data = ", ".join(draw(st.lists(_hex, min_size=1, max_size=6)))
            out.append(f"Ext_User_Prm_Data_Const({draw(st.integers(0, 232))}) = {data}\n")
        else:
            out.append(f"Ext_User_Prm_Data_Ref({draw(st.integers(0, 40))}) = {draw(st.integers(1, 6))}\n")
    return "".join(out)


@st.composite
def structured_gsd(draw):
    head = ["#Profibus_DP\n", "Ident_Number = 0x1234\n", "Modular_Station = 1\n",
            f"Max_Module = {draw(st.integers(1, 4))}\n"]
    if draw(st.booleans()):
        head.append(f"User_Prm_Data_Len = {draw(st.integers(0, 300))}\n")
    if draw(st.booleans()):
        head.append("User_Prm_Data = " + ", ".join(draw(st.lists(_hex, min_size=1, max_size=5))) + "\n")
    head.append('PrmText = 1\nText(0) = "zero"\nText(1) = "one"\nText(-1) = "minus"\nEndPrmText\n')
    defs = [draw(ext_user_prm_data(r)) for r in range(1, draw(st.integers(1, 6)) + 1)]
    mods = []
    for i in range(draw(st.integers(1, 4))):
        cfg = ", ".join(draw(st.lists(st.one_of(_compact, _compact, _special), min_size=1, max_size=4)))
        length = f"Ext_Module_Prm_Data_Len = {draw(st.integers(0, 40))}\n" if draw(st.booleans()) else ""
        mods.append(f'Module = "M{i}" {cfg}\n{i + 1}\n{length}{draw(prm_lines())}EndModule\n')
    lines = "".join(head + defs + [draw(prm_lines())] + mods).splitlines(keepends=True)
    action = draw(st.sampled_from(["keep", "keep", "drop", "mangle"]))
    if action != "keep" and lines:
        i = draw(st.integers(0, len(lines) - 1))
        if action == "drop":
            del lines[i]
        else:
            j = draw(st.integers(0, len(lines[i])))
            lines[i] = lines[i][:j] + draw(st.sampled_from(['"', "(", ")", "-", ",", "x", ";", "\\", "=", "9",
                                                            "0x1FF", "8"])) + lines[i][j:]
    return "".join(lines)


def _exercise(g) -> None:
    """Interpretation of whatever parsed: only UsageError may come out."""
    selections = [[]] + [[m] for m in g.modules[:4]] + [g.modules[:3]]
    for sel in selections:
        try:
            build_prm(g, sel, {"a": 1} if sel else None).explain()
        except UsageError:
            pass
    for data in (b"", b"\x05\x81\x00\x00\xff", b"\x03\xff", b"\x40\x42\x80\x83\x07"):
        decode_unit_diag(g, data)
    for b in (9600, "12M", "1.5M"):
        g.max_tsdr(b)


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(gsd_like)
def test_gsd_like_text_only_raises_datafileerror(text):
    try:
        g = parse_gsd_text(text, "fuzz.gsd")
    except DataFileError as e:
        assert str(e).startswith("fuzz.gsd")
        return
    _exercise(g)


@settings(max_examples=300, deadline=None)
@given(st.text(max_size=400))
def test_random_text_only_raises_datafileerror(text):
    try:
        g = parse_gsd_text(text, "fuzz.gsd")
    except DataFileError:
        return
    _exercise(g)


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=300))
def test_random_bytes_with_header_only_raise_datafileerror(data):
    try:
        g = parse_gsd_bytes(b"#Profibus_DP\r\n" + data, "fuzz.gsd")
    except DataFileError:
        return
    _exercise(g)


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=64))
def test_decode_unit_diag_never_raises(data):
    g = parse_gsd_text("#Profibus_DP\nUnit_Diag_Bit(0) = \"a\"\nUnit_Diag_Area = 3-12\nValue(1) = \"b\"\n"
                       "Unit_Diag_Area_End\nUnitDiagType = 129\nX_Unit_Diag_Bit(9) = \"x\"\nEndUnitDiagType\n")
    out = decode_unit_diag(g, data)
    assert all(isinstance(s, str) for s in out)


@settings(max_examples=500, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(structured_gsd())
def test_structured_gsd_only_raises_datafileerror_then_usageerror(text):
    try:
        g = parse_gsd_text(text, "fuzz.gsd")
    except DataFileError as e:
        assert str(e).startswith("fuzz.gsd:")
        return
    _exercise(g)
    for m in g.modules:                      # every module alone, with an override of each parameter
        for d in g.ext_user_prm_data.values():
            for v in (d.default, "one", -1, 2**40):
                try:
                    r = build_prm(g, [m], {d.name: v})
                except UsageError:
                    continue
                assert len(r.user_prm) <= 237
                assert r.cfg == m.cfg


# ---- mutated real files, through the whole command (the seeded subset of tools/fuzz_files.py)

def _fuzz_tool():
    import importlib.util
    from pathlib import Path
    path = Path(__file__).resolve().parent.parent / "tools" / "fuzz_files.py"
    spec = importlib.util.spec_from_file_location("fuzz_files", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_mutated_library_gsd_files_give_exit_0_or_2_never_a_crash(tmp_path, monkeypatch):
    """300 seeded mutations of the library's GSD files (huge numbers, truncation, byte flips, swapped
    lines) through `gsd show --json`: every run ends with exit 0 or 2 and no traceback, within 5 s."""
    import signal
    fz = _fuzz_tool()
    monkeypatch.delenv("PDRIVE_GSD_DIR", raising=False)
    old = signal.signal(signal.SIGALRM, fz._alarm)
    try:
        c = fz.fuzz("gsd", 300, seed=2024, hang_s=5.0, out_dir=None, tmp=tmp_path)
    finally:
        signal.signal(signal.SIGALRM, old)
    assert (c["crash"], c["hang"]) == (0, 0)
    assert c["exit1"] == 0 and c["exit0"] > 0 and c["exit2"] > 0     # both outcomes were exercised


def test_huge_numbers_in_gsd_are_one_error_with_the_line():
    """A 5000-digit decimal or hex number (over Python's 4300-digit int/str limit) is a DataFileError
    at its line, not a ValueError; so is a 5000-digit module reference."""
    for num, line in (("9" * 5000, 3), ("0x" + "F" * 5000, 3)):
        text = f"#Profibus_DP\nVendor_Name = \"V\"\nIdent_Number = {num}\n"
        try:
            parse_gsd_text(text, "n.gsd")
        except DataFileError as e:
            assert (e.line, "number too long") == (line, e.message.split(" (")[0].split(": ", 1)[1])
        else:
            raise AssertionError("accepted")
    try:
        parse_gsd_text('#Profibus_DP\nModule = "M" 0x11\n' + "1" * 5000 + "\nEndModule\n", "m.gsd")
    except DataFileError as e:
        assert e.line == 3 and "reference number too long" in e.message
    else:
        raise AssertionError("accepted")
