"""pdrive sim-ctl: steer a running `pdrive sim --control HOST:PORT` (sim/control.py) from the shell."""

from __future__ import annotations

import json
import os
import urllib.error
import urllib.request
from typing import Any

import click

from profidrive_cli import BusError, UsageError
from profidrive_cli.cli.common import emit_json, out

#: the command's argument words -> the control's JSON arguments
SHAPES: dict[str, tuple[str, ...]] = {
    "state": (), "trip": ("station", "alarm?"), "clear": ("station",), "unplug": ("station",),
    "replug": ("station",), "set": ("station", "code", "value"), "faults": ("spec",),
}


@click.command("sim-ctl")
@click.option("--control", default=None, metavar="HOST:PORT",
              help="Where `pdrive sim --control` serves the plant's control (default: $PDRIVE_SIM_CONTROL).")
@click.option("--token", default=None, help="The token the simulator printed (a control not on "
              "127.0.0.1 asks for it; default: $PDRIVE_SIM_TOKEN).")
@click.option("--json", "as_json", is_flag=True, help="Print the answer as JSON.")
@click.argument("command", type=click.Choice(sorted(SHAPES)))
@click.argument("args", nargs=-1)
def simctl_cmd(control: str | None, token: str | None, as_json: bool, command: str,
               args: tuple[str, ...]) -> None:
    """Steer a running simulator: trip STATION [ALARM], clear STATION, unplug STATION, replug
    STATION, set STATION CODE VALUE, faults 'drop=0.1,noise=0.05' ('' for none), state."""
    control = control or os.environ.get("PDRIVE_SIM_CONTROL")
    if not control:
        raise UsageError("sim-ctl: no --control HOST:PORT (the address `pdrive sim --control` printed)")
    from profidrive_cli.cli.sim_cmd import _host_port
    # the simulator prints its control as a URL (http://HOST:PORT): take that as well as HOST:PORT
    where = control[len("http://"):].rstrip("/") if control.lower().startswith("http://") else control
    host, port = _host_port(where, "--control", lowest=1)
    token = token or os.environ.get("PDRIVE_SIM_TOKEN")
    body = _arguments(command, args)
    url = f"http://{f'[{host}]' if ':' in host else host}:{port}/{command}"
    try:
        req = urllib.request.Request(url, data=None if command == "state" else json.dumps(body).encode(),
                                     method="GET" if command == "state" else "POST",
                                     headers={"Content-Type": "application/json",
                                              **({"Authorization": f"Bearer {token}"} if token else {})})
    except ValueError as e:                 # a HOST urllib cannot put in a URL
        raise UsageError(f"--control {control[:80]!r}: not HOST:PORT ({e})") from None
    try:
        with urllib.request.urlopen(req, timeout=15) as r:
            answer = json.loads(r.read() or b"{}")
    except urllib.error.HTTPError as e:
        try:
            why = json.loads(e.read() or b"{}").get("error") or e.reason
        except ValueError:
            why = e.reason
        if e.code in (400, 404):
            raise UsageError(f"sim-ctl {command}: {why}") from None
        raise BusError(f"sim-ctl: {control}: {why}") from None
    except (urllib.error.URLError, OSError, ValueError) as e:
        reason = getattr(e, "reason", e)
        raise BusError(f"sim-ctl: no simulator control at {control} ({reason})") from None
    if as_json:
        emit_json(answer)
    elif command == "state":
        for st in answer.get("stations", []):
            bits = [f"{k} {v}" for k, v in st.items() if k not in ("station",) and v is not None]
            out.print(f"station {st['station']}: " + ", ".join(bits), markup=False)
        out.print(f"faults: {_faults_words(answer)}", markup=False)
    elif command == "faults":
        out.print(f"faults {_faults_words(answer)}", markup=False)
    else:
        out.print(", ".join(f"{k} {v}" for k, v in answer.items()), markup=False)


def _faults_words(answer: dict[str, Any]) -> str:
    """The injected faults as `sim-ctl faults` takes them (`faults_spec`: sim/control.py faults_answer), or none."""
    spec = answer.get("faults_spec")
    if spec is None:                    # (a simulator before faults_spec: the rates alone)
        spec = ",".join(f"{k}={v:g}" for k, v in (answer.get("faults") or {}).items())
    return spec or "none"


def _arguments(command: str, args: tuple[str, ...]) -> dict[str, object]:
    shape = SHAPES[command]
    need = [a for a in shape if not a.endswith("?")]
    if not len(need) <= len(args) <= len(shape):
        raise UsageError(f"sim-ctl {command} takes {' '.join(a.upper() for a in shape) or 'nothing'}")
    body: dict[str, object] = {}
    for name, value in zip(shape, args):
        name = name.rstrip("?")
        if name == "station":
            if not (value.isascii() and value.isdigit()):
                raise UsageError(f"sim-ctl {command}: station {value!r} is not an address")
            body[name] = int(value)
        elif name == "value":
            try:
                body[name] = float(value)
            except ValueError:
                raise UsageError(f"sim-ctl {command}: {value!r} is not a number") from None
        else:
            body[name] = value
    return body
