"""Mutation testing for the modules where a silent bug moves a motor or corrupts data.

Not part of CI: a habit. For each module below, mutmut (v3, `pip install '.[mutation]'`) changes
the code one small edit at a time (a constant, a comparison, an operator, a returned value) and runs
only that module's own tests against each change. A mutant the tests do not notice ("survived") is
either a missing test or an equivalent change; kill it with a test or list it, with the reason it
is equivalent, in tools/mutation/survivors.md.

    python tools/mutation/run.py                       # every module, one after another
    python tools/mutation/run.py fdl/frames.py dp/cfg.py
    python tools/mutation/run.py --list                # the modules and their tests
    python tools/mutation/run.py dp/services.py --survivors   # also print each survivor's diff

Bounded: each module runs niced (nice -n 10), with at most --jobs test processes (default 2, the
machine is shared) and a --timeout per module (default 900 s; the score then counts only the
mutants checked so far and says so). Each module runs in its own scratch copy of the project
(--workdir, default $TMPDIR/pdrive-mutation/<module>), so the worktree is never touched and each
module has its own [tool.mutmut] section; ../shared is linked beside the copy for the tests that
read it. Prints one line per module: killed / checked, the score, survivors, time.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PKG = "profidrive_cli"

_CHECKLIST_TESTS = ["tests/test_checklist_steps_mutants.py", "tests/test_checklist_bands.py", "tests/test_checklist.py",
                 "tests/test_checklist_steps.py", "tests/test_run_step_standstill.py",
                 "tests/test_run_step_together.py"]

#: module (under profidrive_cli/) -> the tests that are about it
MODULES: dict[str, list[str]] = {
    "fdl/frames.py": ["tests/test_fdl_frames.py", "tests/test_frames_edges.py"],
    "fdl/fcb.py": ["tests/test_fcb.py", "tests/test_fcb_slave.py", "tests/test_lost_reply.py"],
    "fdl/master.py": ["tests/test_fdl_master_mutants.py", "tests/test_master_sim.py", "tests/test_fcb.py", "tests/test_lost_reply.py",
                      "tests/test_babble.py", "tests/test_parity.py"],
    "dp/services.py": ["tests/test_dp_services.py", "tests/test_watchdog_factors.py",
                       "tests/test_dp_services_edges.py"],
    "dp/cfg.py": ["tests/test_dp_services.py", "tests/test_cfg_identifiers.py"],
    "dp/station.py": ["tests/test_station_mutants.py", "tests/test_master_sim.py", "tests/test_sim_slave.py", "tests/test_lost_reply.py"],
    "fdl/timing.py": ["tests/test_fdl_timing_mutants.py", "tests/test_bus_timing_reference.py", "tests/test_timed_sim.py"],
    "fdl/fast.py": ["tests/test_fast_path_mutants.py", "tests/test_fdl_master_mutants.py", "tests/test_dx_fast.py", "tests/test_master_sim.py"],
    "dp/dx_fast.py": ["tests/test_fast_path_mutants.py", "tests/test_reply_lag_mutants.py", "tests/test_poller_waits.py",
                      "tests/test_dx_fast.py", "tests/test_master_sim.py"],
    "drives/profidrive/ppo.py": ["tests/test_profidrive_core.py", "tests/test_profidrive_sim.py"],
    "drives/profidrive/words.py": ["tests/test_words_mutants.py", "tests/test_profidrive_core.py", "tests/test_profidrive_sim.py"],
    "drives/profidrive/scaling.py": ["tests/test_scaling_mutants.py", "tests/test_profidrive_core.py", "tests/test_profidrive_sim.py"],
    "drives/profidrive/pkw.py": ["tests/test_pkw_mutants.py", "tests/test_profidrive_core.py", "tests/test_profidrive_sim.py"],
    "drives/profidrive/pnu.py": ["tests/test_profidrive_core.py", "tests/test_profidrive_sim.py"],
    "drives/profidrive/config.py": ["tests/test_profidrive_core.py", "tests/test_profidrive_sim.py"],
    "drives/profidrive/params.py": ["tests/test_profidrive_core.py", "tests/test_profidrive_sim.py"],
    "drives/profidrive/drive.py": ["tests/test_profidrive_core.py", "tests/test_profidrive_sim.py"],
    "drives/profidrive/describe.py": ["tests/test_profidrive_core.py", "tests/test_profidrive_sim.py"],
    "drives/fuji/config.py": ["tests/test_fuji_vectors.py", "tests/test_fuji_sim.py"],
    "drives/fuji/codes.py": ["tests/test_fuji_mutants.py", "tests/test_fuji_vectors.py", "tests/test_fuji_sim.py"],
    "drives/fuji/drive.py": ["tests/test_fuji_mutants.py", "tests/test_fuji_vectors.py", "tests/test_fuji_sim.py"],
    "drives/fuji/describe.py": ["tests/test_fuji_vectors.py", "tests/test_fuji_sim.py"],
    "drives/fuji/formats.py": ["tests/test_fuji_mutants.py", "tests/test_fuji_vectors.py", "tests/test_fuji_sim.py"],
    "drives/values.py": ["tests/test_values_mutants.py", "tests/test_exact_values.py"],
    "drives/moeller.py": ["tests/test_moeller_mutants.py", "tests/test_moeller_codec.py", "tests/test_moeller_sim.py"],
    "drives/toyo/config.py": ["tests/test_toyo_vectors.py", "tests/test_toyo_sim.py"],
    "drives/toyo/codec.py": ["tests/test_toyo_codec_mutants.py", "tests/test_toyo_vectors.py", "tests/test_toyo_sim.py"],
    "drives/toyo/params.py": ["tests/test_toyo_vectors.py", "tests/test_toyo_sim.py"],
    "drives/toyo/describe.py": ["tests/test_toyo_vectors.py", "tests/test_toyo_sim.py"],
    "drives/toyo/drive.py": ["tests/test_toyo_vectors.py", "tests/test_toyo_sim.py"],
    "drives/yaskawa/codec.py": ["tests/test_yaskawa_codec_mutants.py", "tests/test_yaskawa_codec.py", "tests/test_yaskawa_drive.py"],
    "drives/yaskawa/paramaccess.py": ["tests/test_yaskawa_paramaccess_mutants.py", "tests/test_yaskawa_codec.py", "tests/test_yaskawa_drive.py"],
    "drives/yaskawa/config.py": ["tests/test_yaskawa_codec.py", "tests/test_yaskawa_drive.py"],
    "drives/yaskawa/describe.py": ["tests/test_yaskawa_codec.py", "tests/test_yaskawa_drive.py"],
    "drives/yaskawa/drive.py": ["tests/test_yaskawa_codec.py", "tests/test_yaskawa_drive.py"],
    "session/safestop.py": ["tests/test_safestop_mutants.py", "tests/test_stop_drives.py", "tests/test_escalation.py",
                            "tests/test_session.py"],
    "session/restore.py": ["tests/test_restore_mutants.py", "tests/test_exact_values.py", "tests/test_session.py",
                           "tests/test_param_factory.py"],
    "session/motion.py": ["tests/test_motion_mutants.py", "tests/test_motion.py", "tests/test_safestop_mutants.py",
                          "tests/test_session.py", "tests/test_jog.py", "tests/test_torque.py"],
    "session/parameters.py": ["tests/test_parameters_mutants.py", "tests/test_param_plan.py", "tests/test_restore_mutants.py",
                              "tests/test_exact_values.py",
                              "tests/test_session.py"],
    # the asyncio face: a cancelled run must stop its drive (issue 29)
    "aio/__init__.py": ["tests/test_aio.py", "tests/test_aio_mutants.py"],
    "checklist/runner.py": ["tests/test_checklist_bands.py", "tests/test_checklist.py"],
    "checklist/fields.py": _CHECKLIST_TESTS,
    "checklist/steps/run.py": _CHECKLIST_TESTS,
    "checklist/steps/read.py": _CHECKLIST_TESTS,
    "checklist/steps/write.py": _CHECKLIST_TESTS,
    "checklist/steps/expect_status.py": _CHECKLIST_TESTS,
}

#: tests no mutant run can use: they depend on wall-clock timing over a pty, which the loaded
#: machine of a mutation run upsets (a retry counted where none is expected)
DESELECT = ["tests/test_dx_fast.py::test_fast_path_over_a_pty",
            "tests/test_lost_reply.py::test_lost_replies_over_a_real_pty_never_reparameterise"]

COPY = ("profidrive_cli", "tests", "profiles", "gsd", "tools", "examples", "docs", "pyproject.toml")


def scratch_copy(module: str, tests: list[str], workdir: Path) -> Path:
    if workdir.exists():
        shutil.rmtree(workdir)
    workdir.mkdir(parents=True)
    proj = workdir / "project"
    proj.mkdir()
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", ".pytest_cache", ".hypothesis")
    for name in COPY:
        src = ROOT / name
        if src.is_dir():
            shutil.copytree(src, proj / name, ignore=ignore)
        else:
            shutil.copy2(src, proj / name)
    shared = ROOT.parent / "shared"
    if shared.is_dir():
        # tests find ../shared beside the project; mutmut runs them from project/mutants
        (workdir / "shared").symlink_to(shared)
        (proj / "shared").symlink_to(shared)
    cfg = "\n".join([
        "", "[tool.mutmut]",
        f'source_paths = ["{PKG}"]',
        f'only_mutate = ["*{PKG}/{module}"]',
        'also_copy = ["profiles/", "gsd/", "tools/", "examples/", "docs/"]',   # tests run tools/gen_moeller_profile.py; the checklist tests read examples/ and docs/
        "pytest_add_cli_args_test_selection = [" + ", ".join(f'"{t}"' for t in tests) + "]",
        # "-n", "0": one process (pyproject's addopts run the suite in 4 xdist workers)
        'pytest_add_cli_args = ["-p", "no:cacheprovider", "-n", "0", "-x", "-q"'
        + "".join(f', "--deselect", "{t}"' for t in DESELECT) + "]",
        "use_git_change_detection = false",
        "",
    ])
    with open(proj / "pyproject.toml", "a", encoding="utf-8") as f:
        f.write(cfg)
    return proj


def read_results(proj: Path) -> dict[str, str]:
    """mutant name -> status, from `mutmut results --all true` (falls back to the .meta files)."""
    out: dict[str, str] = {}
    r = subprocess.run([sys.executable, "-m", "mutmut", "results", "--all", "true"], cwd=proj,
                       capture_output=True, text=True)
    for line in r.stdout.splitlines():
        m = re.match(r"\s*(\S+__mutmut_\d+): (.+)$", line)
        if m:
            out[m.group(1)] = m.group(2).strip()
    if out:
        return out
    for meta in (proj / "mutants").rglob("*.meta"):
        try:
            data = json.loads(meta.read_text())
        except (OSError, ValueError):
            continue
        for name, code in data.get("exit_code_by_key", {}).items():
            out[name] = ("not checked" if code is None else "killed" if code not in (0, 5, 33, 34)
                         else "survived" if code == 0 else f"exit {code}")
    return out


def run_module(module: str, tests: list[str], args) -> dict:
    workdir = Path(args.workdir) / module.replace("/", "_").removesuffix(".py")
    proj = scratch_copy(module, tests, workdir)
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")
    cmd = ["nice", "-n", str(args.nice), sys.executable, "-m", "mutmut", "run",
           "--max-children", str(args.jobs)]
    t0 = time.monotonic()
    log = open(workdir / "mutmut.log", "w", encoding="utf-8")
    p = subprocess.Popen(cmd, cwd=proj, env=env, stdout=log, stderr=subprocess.STDOUT,
                         start_new_session=True)
    timed_out = False
    try:
        p.wait(timeout=args.timeout)
    except subprocess.TimeoutExpired:
        timed_out = True
        os.killpg(p.pid, signal.SIGTERM)        # this run's own process group only
        try:
            p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()
    log.close()
    took = time.monotonic() - t0
    res = read_results(proj)
    killed = sum(1 for s in res.values() if s in ("killed", "timeout", "segfault"))
    survived = sorted(n for n, s in res.items() if s in ("survived", "suspicious"))
    checked = killed + len(survived)
    # "no tests": no selected test runs that function at all (a gap too, listed apart)
    untested = sorted(n for n, s in res.items() if s == "no tests")
    out = {"module": module, "mutants": len(res), "checked": checked, "killed": killed,
           "survived": survived, "no_tests": untested,
           "score": (killed / checked) if checked else None,
           "seconds": round(took), "timed_out": timed_out, "returncode": p.returncode,
           "workdir": str(workdir)}
    if args.survivors:
        out["diffs"] = {n: subprocess.run([sys.executable, "-m", "mutmut", "show", n], cwd=proj,
                                          capture_output=True, text=True).stdout for n in survived}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("modules", nargs="*", help="modules under profidrive_cli/ (default: all listed)")
    ap.add_argument("--list", action="store_true", help="print the modules and their tests")
    ap.add_argument("--jobs", type=int, default=2, help="test processes at once (default 2)")
    ap.add_argument("--timeout", type=float, default=900, help="seconds per module (default 900)")
    ap.add_argument("--nice", type=int, default=10)
    ap.add_argument("--workdir", default=os.path.join(tempfile.gettempdir(), "pdrive-mutation"))
    ap.add_argument("--survivors", action="store_true", help="print each survivor's diff")
    ap.add_argument("--json", action="store_true", help="one JSON object per module")
    args = ap.parse_args(argv)
    if args.list:
        for m, t in MODULES.items():
            print(f"{m:24} {' '.join(t)}")
        return 0
    try:
        import mutmut  # noqa: F401
    except ImportError:
        print("mutmut is not installed: pip install '.[mutation]'", file=sys.stderr)
        return 2
    chosen = args.modules or list(MODULES)
    unknown = [m for m in chosen if m not in MODULES]
    if unknown:
        print(f"unknown module(s) {', '.join(unknown)}; known: {', '.join(MODULES)}", file=sys.stderr)
        return 2
    worst = 0
    for m in chosen:
        r = run_module(m, MODULES[m], args)
        if args.json:
            print(json.dumps({k: v for k, v in r.items()}), flush=True)
        else:
            score = "n/a" if r["score"] is None else f"{100 * r['score']:.1f} %"
            note = " (timed out: partial)" if r["timed_out"] else ""
            print(f"{m:24} {r['killed']:4d} / {r['checked']:4d} killed  {score:>8}  "
                  f"{len(r['survived'])} survived, {len(r['no_tests'])} in code no selected test "
                  f"runs  {r['seconds']} s{note}", flush=True)
            for n in r["survived"]:
                print(f"    survived: {n}")
                if args.survivors:
                    print(r["diffs"][n])
        if r["checked"] == 0:
            worst = max(worst, 1)
            print(f"    no mutant checked: see {r['workdir']}/mutmut.log", file=sys.stderr)
    return worst


if __name__ == "__main__":
    sys.exit(main())
