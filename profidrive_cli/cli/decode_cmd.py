"""`pdrive decode`: decode a captured output (request) or input (response) area offline."""

from __future__ import annotations

import json
from typing import Any

import click

from profidrive_cli import UsageError
from profidrive_cli.dp.cfg import parse_hex


@click.command("decode")
@click.argument("profile")
@click.argument("hex_octets", nargs=-1, required=True, metavar="HEX...")
@click.option("--ppo", type=int, default=None, metavar="N", help="PPO type 1..5 (layout ppoN)")
@click.option("--format", "layout_name", default=None, metavar="NAME",
              help="a non-PPO layout of the profile, e.g. extended1 (see the profile's layouts)")
@click.option("--request", "request", is_flag=True, help="master -> drive (DP output area)")
@click.option("--response", "response", is_flag=True, help="drive -> master (DP input area)")
@click.option("--json", "as_json", is_flag=True, help="print the decoded fields as JSON")
def decode_cmd(profile: str, hex_octets: tuple[str, ...], ppo: int | None, layout_name: str | None,
               request: bool, response: bool, as_json: bool) -> None:
    """Decode a captured area of PROFILE's layout into named fields.

    HEX is the area as hex octets or words, with or without spaces:
    pdrive decode moeller --ppo 1 --request 3017 0000 0000 0190 047F 2000
    """
    from profidrive_cli.drives import decode_area
    from profidrive_cli.drives.profile import load_profile

    if request and response:
        raise UsageError("give either --request or --response, not both: one area is decoded")
    direction = "request" if request else "response" if response else None
    if direction is None:
        raise UsageError("say which area this is: --request (master -> drive) or --response")
    if ppo is not None and layout_name is not None:
        raise UsageError("give either --ppo N or --format NAME, not both")
    prof = load_profile(profile)
    if ppo is not None:
        layout = f"ppo{ppo}"
        if layout not in prof.layouts:
            ppos = sorted(n for n in prof.layouts if n.startswith("ppo"))
            raise UsageError(f"{prof.name} has no PPO{ppo} "
                             f"(it has: {', '.join(p.upper() for p in ppos) or 'no PPO layouts'})")
    elif layout_name is not None:
        layout = layout_name
        if layout not in prof.layouts:
            raise UsageError(f"{prof.name} has no layout '{layout}' "
                             f"(known: {', '.join(prof.layouts)})")
    else:
        layout = prof.default_layout
    try:
        data = parse_hex(" ".join(hex_octets))
    except ValueError as e:
        raise UsageError(f"bad hex: {e}") from None
    want = prof.layouts[layout].output_len if direction == "request" \
        else prof.layouts[layout].input_len
    if len(data) != want:
        raise UsageError(f"{prof.name} {layout} {direction} is {want} octets, got {len(data)}")
    try:
        result = decode_area(prof, layout, direction, data)
    except ValueError as e:
        raise UsageError(str(e)) from None
    if as_json:
        click.echo(json.dumps(_result_json(result), indent=2, ensure_ascii=False, default=str))
    else:
        for line in result.get("text", []):
            click.echo(line)


#: the speed words' keys: reference_* for what the master sends, actual_* for what the drive
#: reports (docs/json.md: the same names as status and run)
_REF = {"hz": "reference_hz", "percent": "reference_percent", "max_hz": "fmax_hz"}
_ACT = {"hz": "actual_hz", "percent": "actual_percent", "max_hz": "fmax_hz"}
_SPEED_NAMES = {"reference": _REF, "frequency_reference": _REF,
                "actual": _ACT, "speed_feedback": _ACT, "output_frequency": _ACT,
                "motor_speed": _ACT}


def _result_json(result: dict[str, Any]) -> dict[str, Any]:
    """decode_area's dict in the contract's shape: octets in lower-case hex, each word's bits that
    are set as `flags` (a list of names), reference_hz / actual_hz."""
    from profidrive_cli.cli.jsonout import flag_list, octets, renamed
    d = dict(result)
    if "octets" in d:
        d["octets"] = octets(d["octets"])
    def word(key: str | None, value: Any) -> Any:
        if not isinstance(value, dict):
            return value
        if key in _SPEED_NAMES:
            value = renamed(value, _SPEED_NAMES[key])
        if isinstance(value.get("set"), list):
            value = renamed(value, {"set": "flags"})
        if isinstance(value.get("flags"), dict):
            value = {**value, "flags": flag_list(value["flags"])}
        return value

    for key, value in d.items():
        if isinstance(value, list) and key in ("fields", "pzd"):
            d[key] = [word(v.get("field") if isinstance(v, dict) else None, v) for v in value]
        else:
            d[key] = word(key, value)
    return d
