#!/usr/bin/env python3
"""Generate the parameter table of profiles/moeller-de6-net-dp.yaml from the spec's CSV.

    python tools/gen_moeller_profile.py [CSV] [--check]

CSV defaults to ../shared/spec/moeller-de6-parameters.csv (378 rows, the cross-reference list of the
Moeller DE6-NET-DP manual). The script rewrites only the block between the markers
"# >>> generated parameters" and "# <<< generated parameters" in the profile; everything else in the
YAML is maintained by hand. --check exits 1 if the file would change (for CI).

Per row: code (keypad code; PNU<n> where the list prints none or a duplicate), name, pnu, unit, scale
(= 1 / multiplier), min/max (engineering units, from the printed range), access (R/W -> rw,
R/WOS -> stop, RO -> ro), bytes (1, 2, 4 on the wire) and size (16 or 32 bits), signed where the range
is negative. Family keys: bytes, format (code | hex | baud | alarm947), ranges (several allowed intervals), df6 (false
= not on DF6), df6_max, note, dangerous + danger (the common keys). The decisions behind the special cases are in the profile's
`decisions:` list.
"""

from __future__ import annotations

import csv
import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PROFILE = ROOT / "profiles" / "moeller-de6-net-dp.yaml"
DEFAULT_CSV = ROOT.parent / "shared" / "spec" / "moeller-de6-parameters.csv"
BEGIN = "# >>> generated parameters"
END = "# <<< generated parameters"

SCALE = {"*1": 1, "*10": 0.1, "*100": 0.01, "*1000": 0.001, "Code": 1, "Bit": 1,
         "*1/10": 10}
ACCESS = {"R/W": "rw", "R/WOS": "stop", "RO": "ro"}
UNIT = {"(%)": "%", "pls": "pulses", "Bits": "bits", "times": "", "hex": ""}

# parameters whose writing erases settings or moves the motor on its own (issue 12; the profile's
# decisions say why): `dangerous: true` and what happens, in words
DANGER = {
    261: "selects what an initialisation erases (1 = the fault history, 2 = the fault history and every "
         "setting back to factory values)",
    321: "arms motor auto-tuning: the next run command measures the motor instead of running it at the "
         "reference (2 = the motor turns during the measurement) and overwrites the motor constants",
}

# names printed damaged in the manual (our wording)
NAME_FIX = {
    171: "Level of detecting zero speed",
    196: "Sampling count of the analogue input (name truncated in the manual)",
    344: "Adjustment of analogue input terminal, 1st of 3 (terminal name lost in the manual)",
    345: "Adjustment of analogue input terminal, 2nd of 3 (terminal name lost in the manual)",
    346: "Adjustment of analogue input terminal, 3rd of 3 (terminal name lost in the manual)",
    348: "Zero adjustment of analogue input terminal, 1st of 3 (terminal name lost in the manual)",
    349: "Zero adjustment of analogue input terminal, 2nd of 3 (terminal name lost in the manual)",
    350: "Zero adjustment of analogue input terminal, 3rd of 3 (terminal name lost in the manual)",
    354: "Pointer to the latest trip record (00..05: 00 = record 1, assumed)",
}

# our notes on rows the manual prints oddly
NOTES = {
    35: "R/WOS in the list although the other accel/decel times are R/W",
    38: "signed (negative frequencies allowed); two's complement assumed",
    39: "signed (negative frequencies allowed); two's complement assumed",
    62: "reference for the N2 set-point and actual value (0x4000 = 100 % of A004)",
    74: "multiplier printed x100 although the range has three decimals; we follow the multiplier (0.01 steps)",
    75: "multiplier printed x100 although the range has three decimals; we follow the multiplier (0.01 steps)",
    84: "multiplier printed x100 although the range has three decimals; we follow the multiplier (0.01 steps)",
    85: "multiplier printed x100 although the range has three decimals; we follow the multiplier (0.01 steps)",
    129: "printed range 0..65535 in units of 10 h with multiplier 1/10: one count = 10 h",
    136: "two ranges, one per voltage class (200 V / 400 V class)",
    189: "2 = operator: the card writes the frequency reference (bus reference)",
    190: "1 = terminal: the card writes the run commands (bus commands)",
    197: "signed one-octet value; two's complement assumed",
    198: "signed one-octet value; two's complement assumed",
    332: "communication-loss reaction for a card in slot 1 (0 = trip E6x, 1 = keep running)",
    333: "communication-loss reaction for a card in slot 2, where this card sits "
         "(0 = trip E7x, 1 = keep running)",
    340: "same counter as d016 (PNU 401); listed twice in the manual",
    341: "same counter as d017 (PNU 402); listed twice in the manual",
    354: "printed with the d081 marker; we give d081 to the first row of trip record 1 (PNU 355)",
    409: "signed; two's complement assumed",
}

TRIP_FIELDS = ["factor and status", "frequency", "output current", "DC-bus voltage",
               "running time", "power-on time"]

# PROFIdrive-specific parameters of the card (not in the CSV; manual table 6)
PROFIDRIVE_ROWS = [
    dict(code="PNU915", name="PZD assignment, set-point telegram (PZD3..PZD10)", pnu=915, min=0,
         max=418, access="rw", bytes=2, array=8,
         note="subindex n = PNU carried in output word PZD(n+2); 0 = word unused; volatile until saved"),
    dict(code="PNU916", name="PZD assignment, actual-value telegram (PZD3..PZD10)", pnu=916, min=0,
         max=418, access="rw", bytes=2, array=8,
         note="subindex n = PNU carried in input word PZD(n+2); 0 = word unused; volatile until saved"),
    dict(code="PNU918", name="PROFIBUS node address", pnu=918, min=1, max=99, access="ro", bytes=2),
    dict(code="PNU927", name="Parameter edit rights (PKW)", pnu=927, min=0, max=1, access="rw",
         bytes=2, format="code"),
    dict(code="PNU928", name="Process-data control rights (PZD)", pnu=928, min=0, max=1,
         access="rw", bytes=2, format="code"),
    dict(code="PNU947", name="Fault memory (fault numbers)", pnu=947, min=0, max=79, access="ro",
         bytes=2, array=49, format="alarm947"),   # Table 8 fault numbers, shown with their names
    dict(code="PNU963", name="PROFIBUS baud rate (code)", pnu=963, min=0, max=9, access="ro",
         bytes=2, format="baud"),          # the card's own coding, spec 6.3 (src L716-728)
    dict(code="PNU964", name="Device identification", pnu=964, min=0, max=0xFFFF, access="ro",
         bytes=2, format="hex"),
    dict(code="PNU965", name="PROFIdrive profile version", pnu=965, min=0, max=0xFFFF,
         access="ro", bytes=2),
    dict(code="PNU967", name="Last control word received", pnu=967, min=0, max=0xFFFF,
         access="ro", bytes=2, format="hex"),
    dict(code="PNU968", name="Last status word sent", pnu=968, min=0, max=0xFFFF, access="ro",
         bytes=2, format="hex"),
    dict(code="PNU971", name="Store parameters in non-volatile memory (write 0 then 1)", pnu=971,
         min=0, max=1, access="wo", bytes=2, format="code",
         note="the 0 -> 1 edge stores; about 10 s; inverter must be stopped"),
]


def _num(text: str, hexa: bool):
    text = text.strip().lstrip("+")
    if hexa:
        return int(text, 16)
    v = float(text)
    return int(v) if v.is_integer() and "." not in text else v


def parse_range(pnu: int, text: str):
    """-> (min, max, unit, extra) from the printed range."""
    t = text.replace("\u2013", "-").replace("\u2212", "-").strip()
    extra: dict = {}
    if pnu == 129:                        # "0 to 65535 (*10 hr)", multiplier 1/10
        return 0, 655350, "h", extra
    if pnu == 136:                        # "330 to 380/660 to 760"
        extra["ranges"] = [[330, 380], [660, 760]]
        return 330, 760, "V", extra
    if pnu in (74, 75, 84, 85):          # printed x100 with a 0.001 range: 0.01 is the smallest step
        return 0.01, 9999.0, "kgm\u00b2", extra
    m = re.match(r"^([+-]?[0-9A-Fa-f.]+)\s+to\s+([+-]?[0-9A-Fa-f.]+)\s*(.*)$", t)
    if not m:
        raise ValueError(f"PNU {pnu}: cannot parse range {text!r}")
    lo, hi, rest = m.groups()
    rest = rest.strip()
    hexa = rest.endswith("hex")
    also = []
    if rest.startswith(","):              # "01 to 48, 255"
        also = [int(x) for x in rest[1:].split(",") if x.strip()]
        rest = ""
    unit = UNIT.get(rest, rest)
    lo_v, hi_v = _num(lo, hexa), _num(hi, hexa)
    if hexa:
        extra["format"] = "hex"
    if also:
        extra["ranges"] = [[lo_v, hi_v]] + [[a, a] for a in also]
        hi_v = max([hi_v] + also)
    return lo_v, hi_v, unit, extra


def rows_from_csv(path: Path) -> list[dict]:
    with open(path, encoding="utf-8", newline="") as f:
        rows = list(csv.DictReader(f))
    if len(rows) != 378:
        raise SystemExit(f"{path}: expected 378 rows, found {len(rows)}")
    out = []
    seen: dict[str, int] = {}
    trip_block = None
    for r in rows:
        pnu = int(r["PROFIBUS PNU"])
        code_cell = r["DF6/DV6 code"].strip()
        size = int(r["Size [bytes]"])
        mult = r["Multiplier"].strip()
        name = NAME_FIX.get(pnu, r["Name (as printed)"].strip())
        lo, hi, unit, extra = parse_range(pnu, r["Range (unit)"])
        code = code_cell.replace("\u2192", "").strip()
        if 355 <= pnu <= 390:               # trip records d081..d086, 6 PNUs each
            k, off = divmod(pnu - 355, 6)
            trip_block = f"d08{k + 1}"
            code = trip_block if off == 0 else f"PNU{pnu}"
            name = f"Trip record {k + 1} ({trip_block}): {TRIP_FIELDS[off]}"
        elif pnu == 354 or code in ("(blank)", "", "\u2013 (none)", "- (none)") or code in seen \
                or pnu in (340, 341):
            code = f"PNU{pnu}"
        if code in seen:
            raise SystemExit(f"duplicate code {code} (PNU {seen[code]} and {pnu})")
        seen[code] = pnu
        row = {"code": code, "name": name, "pnu": pnu}
        if unit:
            row["unit"] = unit
        scale = SCALE[mult]
        if scale != 1:
            row["scale"] = scale
        row["min"], row["max"] = lo, hi
        row["access"] = ACCESS[r["Access"].strip()]
        row["bytes"] = size
        if size == 4:
            row["size"] = 32
        if isinstance(lo, (int, float)) and lo < 0:
            row["signed"] = True
        if mult == "Code" or pnu == 255:
            row["format"] = "code"
        if mult == "Bit":
            row["format"] = "hex"
        row.update(extra)
        df6 = r["DF6"].strip()
        if df6 == "no":
            row["df6"] = False
        elif df6.startswith("yes, max"):
            v = float(df6.split("max", 1)[1])
            row["df6_max"] = int(v) if v.is_integer() and "." not in df6 else v
        if pnu in NOTES:
            row["note"] = NOTES[pnu]
        if pnu in DANGER:
            row["dangerous"] = True
            row["danger"] = DANGER[pnu]
        out.append(row)
    for p in PROFIDRIVE_ROWS:
        row = dict(p)
        out.append(row)
    return out


def _yaml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, list):
        return "[" + ", ".join(_yaml_value(x) for x in v) + "]"
    return str(v)


def render(rows: list[dict]) -> str:
    lines = [BEGIN + " (tools/gen_moeller_profile.py from moeller-de6-parameters.csv; "
             "do not edit by hand)"]
    lines.append("parameters:")
    for r in rows:
        lines.append("  - {" + ", ".join(f"{k}: {_yaml_value(v)}" for k, v in r.items()) + "}")
    lines.append(END)
    return "\n".join(lines) + "\n"


def main(argv: list[str]) -> int:
    check = "--check" in argv
    args = [a for a in argv if a != "--check"]
    csv_path = Path(args[0]) if args else DEFAULT_CSV
    text = PROFILE.read_text(encoding="utf-8")
    try:
        head, rest = text.split(BEGIN, 1)
        _, tail = rest.split(END, 1)
    except ValueError:
        print(f"{PROFILE}: markers '{BEGIN}' / '{END}' not found", file=sys.stderr)
        return 2
    after_end = tail.split("\n", 1)[1] if "\n" in tail else ""
    new = head + render(rows_from_csv(csv_path)) + after_end
    if check:
        if new != text:
            print(f"{PROFILE} is out of date; run tools/gen_moeller_profile.py", file=sys.stderr)
            return 1
        return 0
    PROFILE.write_text(new, encoding="utf-8")
    print(f"wrote {PROFILE}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
