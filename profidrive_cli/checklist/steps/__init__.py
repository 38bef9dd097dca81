"""The checklist's step types, registered by name in one table.

Each step type is one module here holding its schema (validate, file:line through fields.FieldChecker)
and its execution (execute, on the station's Drive) together; base.py says what a step type implements.
spec.py looks a step's YAML key up in STEPS to validate it, runner.py to run it. The table's order is
the order error messages list the step types in.

Adding a step type: write checklist/steps/<name>.py with a StepType subclass and `STEP = ...`, add the
module to the table below, and document it in docs/checklists.md.
"""

from profidrive_cli.checklist.steps import (baseline, bus_health, comm_loss, expect_identity, expect_status, faults,
                                            jog, note, prompt, read, reset_fault, run, save, stop, wait, write)
from profidrive_cli.checklist.steps.base import StepFailed, StepType

STEPS: dict[str, StepType] = {m.STEP.name: m.STEP for m in (
    expect_identity, read, write, save, run, jog, stop, expect_status, wait, bus_health, faults, reset_fault, prompt,
    note, comm_loss, baseline)}

__all__ = ["STEPS", "StepFailed", "StepType"]
