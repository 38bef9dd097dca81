"""Scripted commissioning checklists (`pdrive checklist run FILE.yaml`).

    spec.py     the YAML format: loading and validation with file:line errors, per station
    runner.py   executes a validated checklist on drives (through drives.session.DriveSession)
    report.py   JSON, Markdown and JUnit XML reports of a run

The format is documented in docs/checklists.md. cli/checklist_cmd.py only renders.
"""

from profidrive_cli.checklist.spec import (Checklist, ChecklistError, StationSpec, Step, load_checklist,
                                           load_checklist_text)

__all__ = ["Checklist", "ChecklistError", "StationSpec", "Step", "load_checklist", "load_checklist_text"]
