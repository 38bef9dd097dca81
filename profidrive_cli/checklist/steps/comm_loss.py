"""Step type `comm_loss`: the comm-loss acceptance test (session/commloss.py) on the station.

    - comm_loss: {hz: 20, mode: silence, timeout: 5, tolerance: 0.35, start_timeout: 30, ack: false}
    - comm_loss: 20                      # shorthand: hz

Runs the drive at hz, breaks the link (silence: the master goes quiet; clear: Global_Control
Clear_Data), measures the reaction and passes only when a look that came back by the limit (watchdog +
configured delay + stop time + tolerance) saw the drive stopped or tripped; a drive set to keep running
without a master, or seen running at or after the limit, fails, and a result the figures cannot decide
(INCONCLUSIVE) fails the step too. The drive is left stopped; the fault is acknowledged only with
ack: true. Needs the station's parameter channel (the configured reaction is read from the drive).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from profidrive_cli.checklist.fields import RawStepFacts, StationFacts, StepArgs, fmt
from profidrive_cli.checklist.steps.base import Handle, R, SR, StepFailed, StepRun, StepType
from profidrive_cli.drives import drive_class

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.checklist.fields import FieldChecker
    from profidrive_cli.drives.base import Drive

MODES = ("silence", "clear")


class CommLoss(StepType):
    name = "comm_loss"

    def validate(self, check: FieldChecker, st: StationFacts, rs: RawStepFacts, body: Any,
                 state: dict[str, bool]) -> tuple[StepArgs, str]:
        d = check.fields(rs, body, ("hz", "mode", "timeout", "tolerance", "start_timeout", "ack"), "hz")
        w = f"step {rs.index} (comm_loss)"
        hz = check.num(rs, d, "hz", default=20.0, positive=True)
        mode = d.get("mode", "silence")
        if mode not in MODES:
            check.fail(d.line_of("mode"), f"{w}: mode must be silence or clear, got {mode!r}")
        timeout = check.num(rs, d, "timeout", positive=True)
        tolerance = check.num(rs, d, "tolerance", minimum=0.0)
        start_timeout = check.num(rs, d, "start_timeout", positive=True)
        ack = d.get("ack", False)
        if not isinstance(ack, bool):
            check.fail(d.line_of("ack"), f"{w}: 'ack' must be true or false, got {ack!r}")
        # a reaction the card fixes (Toyo protection 18) is known without a parameter channel
        if mode == "silence" and not drive_class(st.profile).comm_loss_reaction_fixed:
            check.need_param_channel(st, rs)
        state["running"] = False          # the step leaves the drive stopped
        return ({"hz": hz, "mode": mode, "timeout": timeout, "tolerance": tolerance,
                 "start_timeout": start_timeout, "ack": ack},
                f"comm-loss test at {fmt(hz)} Hz ({mode})" + (", acknowledge the fault" if ack else ""))

    def execute(self, run: StepRun[SR, R], sr: SR, r: R, d: Drive, h: Handle) -> str:
        from profidrive_cli.api.station import run_commloss
        a = r.step.args
        run.progress(sr, r, f"running at {fmt(a['hz'])} Hz, then breaking the link ({a['mode']})")
        res = run_commloss(h.session, float(a["hz"]), a["mode"], timeout=a["timeout"], ack=a["ack"],
                           tolerance=a.get("tolerance"), start_timeout=a.get("start_timeout"))
        doc = res.to_dict()
        doc.pop("event", None)
        r.expected = {"within_s": doc["expected_s"], "limit": doc["limit"],
                      "reaction": res.reaction.words, "watchdog_s": res.watchdog_ms / 1000.0}
        r.measured = doc
        if not res.passed:
            raise StepFailed(res.verdict)
        return res.verdict


STEP = CommLoss()
