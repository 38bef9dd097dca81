"""Profile texts that contain commas survive YAML flow mappings.

In `{name: A, b, c}` an unquoted comma ends the value: the name is cut after "A" and "b" becomes a key
with no value. Every profile is walked for such keys (a key whose value is null); the only null values
allowed are the settings a profile documents as "not set" (listed here with the reason)."""

from pathlib import Path

import yaml

PROFILES = Path(__file__).resolve().parent.parent / "profiles"

#: (file, path of the mapping, key): nulls a profile sets on purpose
DELIBERATE = {
    ("yaskawa-si-p1.yaml", "yaskawa", "rated_current_a"),     # unknown until the user names the motor
    ("yaskawa-si-p1.yaml", "yaskawa", "fast_stop_input"),     # no fast-stop input programmed by default
    ("moeller-de6-net-dp.yaml", "profidrive/ctw_bits", 9),    # "null: bit not used" (the file says so)
    ("moeller-de6-net-dp.yaml", "profidrive/stw_bits", 7),
}


def _nulls(o, path=""):
    if isinstance(o, dict):
        for k, v in o.items():
            if v is None:
                yield path, k
            yield from _nulls(v, f"{path}/{k}" if path else str(k))
    elif isinstance(o, list):
        for x in o:
            yield from _nulls(x, path)


def test_no_text_is_cut_at_a_comma():
    found = {(f.name, p, k) for f in sorted(PROFILES.glob("*.yaml"))
             for p, k in _nulls(yaml.safe_load(f.read_text(encoding="utf-8")))}
    assert found - DELIBERATE == set()


def test_the_toyo_date_words_keep_their_whole_names():
    from profidrive_cli.drives.profile import load_profile
    prof = load_profile("toyo")
    raw = yaml.safe_load((PROFILES / "toyo-pbus66z.yaml").read_text(encoding="utf-8"))
    assert raw["fields"]["month_day"]["name"] == "Month/day (low byte day, high byte month; used when J-14 = 1)"
    assert raw["fields"]["hour_minute"]["name"] == "Hour/minute (low byte minute, high byte hour)"
    fan = [a for a in prof.alarms if a.code == "FAN"][0]
    assert fan.meaning == "Cooling fan failure (warning, the inverter keeps running)"
