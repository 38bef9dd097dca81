"""Scripted commissioning checklists (`pdrive checklist run FILE.yaml`).

    spec.py     the YAML format: header, stations, variables, the step list; loading and validation with
                file:line errors, per station
    fields.py   the field toolkit step types check their fields with (FieldChecker, ParamTarget)
    steps/      one module per step type (schema + execution), registered by name in steps.STEPS
    runner.py   the run loop over a validated checklist on drives (through session.DriveStation),
                safe stop and results
    report.py   JSON, Markdown and JUnit XML reports of a run

The format is documented in docs/checklists.md. cli/checklist_cmd.py only renders.
"""

from profidrive_cli.checklist.spec import (Checklist, ChecklistError, StationSpec, Step, load_checklist,
                                           load_checklist_text)

__all__ = ["Checklist", "ChecklistError", "StationSpec", "Step", "load_checklist", "load_checklist_text"]
