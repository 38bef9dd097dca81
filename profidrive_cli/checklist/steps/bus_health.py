"""Step type `bus_health`: keep the cyclic exchange going for some seconds and judge the station's
bus counters over that time against thresholds — a marginal segment (termination, shielding, stubs,
a baud rate too high for the cable) shows as retries long before the station drops out.

    - bus_health: {seconds: 10, max_retries_per_1000: 10, max_no_answer: 0, max_illegal: 0,
                   max_reparams: 0}

Defaults (decision): a clean RS-485 segment repeats no telegram at all; 10 retries per 1,000
requests (1 %) is the limit a commissioning report accepts before it calls the segment marginal;
one request lost after all retries, one corrupt telegram or one re-parameterisation fails the step.

validate() checks the step's fields for one station (file:line, through the FieldChecker);
execute() runs it on the station's Drive for the Runner. Imports only the checklist toolkits
(fields.py, steps/base.py) and the session's counter arithmetic."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from profidrive_cli.bustools.buswatch import health_figures
from profidrive_cli.checklist.fields import RawStepFacts, StationFacts, StepArgs, fmt
from profidrive_cli.checklist.steps.base import Handle, R, SR, StepFailed, StepRun, StepType

if TYPE_CHECKING:                                   # pragma: no cover
    from profidrive_cli.checklist.fields import FieldChecker
    from profidrive_cli.drives.base import Drive

DEFAULT_SECONDS = 10.0
#: the figures in words
WORDS = {"retries_per_1000": "retries per 1000 requests", "no_answer": "lost", "illegal": "corrupt",
         "reparams": "re-parameterisations"}

#: threshold field -> (the figure it bounds, default)
LIMITS = {
    "max_retries_per_1000": ("retries_per_1000", 10.0),
    "max_no_answer": ("no_answer", 0),
    "max_illegal": ("illegal", 0),
    "max_reparams": ("reparams", 0),
}


class BusHealth(StepType):
    name = "bus_health"

    def validate(self, check: FieldChecker, st: StationFacts, rs: RawStepFacts, body: Any,
                 state: dict[str, bool]) -> tuple[StepArgs, str]:
        d = check.fields(rs, body, ("seconds",) + tuple(LIMITS), "seconds")
        seconds = check.num(rs, d, "seconds", default=DEFAULT_SECONDS, positive=True)
        limits = {k: check.num(rs, d, k, default=default, minimum=0) for k, (_, default) in LIMITS.items()}
        title = (f"bus health over {fmt(seconds)} s: at most {fmt(limits['max_retries_per_1000'])} retries "
                 f"per 1000 requests, {fmt(limits['max_no_answer'])} lost, {fmt(limits['max_illegal'])} "
                 f"corrupt, {fmt(limits['max_reparams'])} re-parameterisations")
        return {"seconds": seconds, **limits}, title

    def execute(self, run: StepRun[SR, R], sr: SR, r: R, d: Drive, h: Handle) -> str:
        a = r.step.args
        sess = h.session
        r.expected = {k: a[k] for k in LIMITS}
        before = dict(sess.counters)
        run.cycle_for(sr, r, d, float(a["seconds"]), "watching the bus counters")
        fig = health_figures(before, dict(sess.counters))
        r.measured = {"duration_s": a["seconds"], **{k: (round(v, 2) if isinstance(v, float) else v)
                                                  for k, v in fig.items()}}
        if not fig["requests"]:
            raise StepFailed("no request reached the station in the measuring time")
        over = [f"{WORDS[figure]} {fmt(round(fig[figure], 2))} > {fmt(a[k])}"
                for k, (figure, _) in LIMITS.items() if fig[figure] > a[k]]
        summary = (f"{fig['requests']} requests: {fig['retries']} retries "
                   f"({fig['retries_per_1000']:.1f} per 1000), {fig['no_answer']} lost, "
                   f"{fig['illegal']} corrupt, {fig['reparams']} re-parameterisations")
        if over:
            raise StepFailed(f"marginal segment: {'; '.join(over)} ({summary})")
        return summary


STEP = BusHealth()
