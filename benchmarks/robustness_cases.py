"""Issue 13's reported cases, run through the CLI against one or more source trees.

Every case the issue lists under "What was measured" (alias bomb, damaged runs, a resume on
another rig, unbounded sizes, tracebacks, accepted nonsense) is built afresh in a temporary
folder by the code under test (damaged runs are made by that code's own sweep, killed or
finished, then damaged), and run as `python -m pianobot ...` in a child process with a memory
cap and a time limit. Each outcome records the exit code, the stderr lines, whether a traceback
was printed, whether anything in the case folder changed, wall time and the child's peak RSS.

A case is *as promised* when it meets the issue's rule: bad input gives exit code 2, exactly
one `error:` line on stderr and leaves every file as it was; good-but-odd input (a byte-order
mark, a 100,000-digit force reading, a 20,000-line log, a 20,000-note song) succeeds with the
right content.

    .venv/bin/python benchmarks/robustness_cases.py                      # this tree
    .venv/bin/python benchmarks/robustness_cases.py --tree before=OLD --tree after=.
    # OLD: a source tree of another commit, e.g. `git archive COMMIT | tar -x -C OLD`

Writes a JSON file and a Markdown table (benchmarks/results/robustness_cases.{json,md}).
The read-only-folder cases need an unprivileged user and are covered by
tests/robustness/test_paths_and_options.py instead; the lock race by test_lock_race.py.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import textwrap
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
FIXTURES = REPO.parent / "shared" / "fixtures" / "zhang2022"
QUICKSTART = REPO / "experiments" / "quickstart.yaml"
SIM_RIG = REPO / "experiments" / "rigs" / "sim-extended.yaml"
RESULTS = REPO / "benchmarks" / "results"
MEMORY_CAP_BYTES = 4 << 30  # a runaway case dies with MemoryError instead of taking the machine

KILL_AFTER = 8  # trials of the quickstart's 16, two per part batch: four batches of parts


@dataclass
class Outcome:
    code: int | None  # None: timed out
    stderr_lines: list[str]
    stdout: str
    seconds: float
    peak_rss_mib: float
    changed: list[str]
    traceback: bool

    def line(self) -> str:
        if self.code is None:
            return "(timed out)"
        text = self.stderr_lines[-1] if self.traceback and self.stderr_lines else (
            self.stderr_lines[0] if self.stderr_lines else "")
        return text


@dataclass
class Case:
    """One reported case: `build(tree, folder)` makes its files and returns the CLI arguments."""

    key: str
    point: str  # the numbered point
    what: str
    build: Callable[[Path, Path], list[str]]
    expect: str = "refused"  # or "ok"
    check: Callable[[Path, Outcome], str | None] | None = None  # for "ok": None or what is wrong
    timeout_s: float = 60.0
    needs_fixtures: bool = False
    verdicts: dict[str, Any] = field(default_factory=dict)


def _env(tree: Path) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(tree)
    env.pop("PIANOBOT_TRACEBACK", None)
    env["COLUMNS"] = "200"
    return env


def _cap_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_CAP_BYTES, MEMORY_CAP_BYTES))
    os.setsid()


def run_child(tree: Path, argv: list[str], cwd: Path, timeout_s: float) -> tuple[int | None, str, str, float, float]:
    """(exit code or None on timeout, stdout, stderr, seconds, peak RSS MiB) of one child."""
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        start = time.perf_counter()
        child = subprocess.Popen(argv, cwd=cwd, env=_env(tree), stdout=out, stderr=err,
                                 stdin=subprocess.DEVNULL, preexec_fn=_cap_memory)
        code: int | None = None
        rss_kib = 0
        while True:
            pid, status, usage = os.wait4(child.pid, os.WNOHANG)
            if pid:
                code = os.waitstatus_to_exitcode(status)
                rss_kib = usage.ru_maxrss
                break
            if time.perf_counter() - start > timeout_s:
                os.killpg(child.pid, signal.SIGKILL)
                _, _, usage = os.wait4(child.pid, 0)
                rss_kib = usage.ru_maxrss
                break
            time.sleep(0.02)
        child.returncode = -1  # reaped above: keep Popen from waiting again
        seconds = time.perf_counter() - start
        out.seek(0)
        err.seek(0)
        return (code, out.read().decode(errors="replace"), err.read().decode(errors="replace"),
                seconds, rss_kib / 1024)


def pianobot(tree: Path, args: list[str], cwd: Path, timeout_s: float = 120.0) -> tuple[int | None, str, str]:
    code, out, err, _, _ = run_child(tree, [sys.executable, "-m", "pianobot", *args], cwd, timeout_s)
    return code, out, err


def _digest(root: Path) -> dict[str, str]:
    out: dict[str, str] = {}
    for path in sorted(root.rglob("*")):
        key = path.relative_to(root).as_posix()
        out[key] = hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else "<dir>"
    return out


# ---- runs to damage, made by the tree under test ---------------------------------------------

_KILL_SCRIPT = textwrap.dedent("""
    import os, sys
    from pathlib import Path
    from pianobot.run import run_sweep
    from pianobot.run.records import TrialDone
    done = [0]
    def stop(record):
        if isinstance(record, TrialDone):
            done[0] += 1
            if done[0] == {kill}:
                os._exit(0)  # like kill -9: no cleanup, no compaction, the lock left behind
    run_sweep(Path(sys.argv[1]), data_dir=Path(sys.argv[2]), progress=False, batch_trials=2,
              subscribers=[stop])
    os._exit(1)
""").format(kill=KILL_AFTER)

_templates: dict[tuple[str, str], Path] = {}


def _template(tree: Path, kind: str, scratch: Path) -> Path:
    """A data folder with one quickstart run, killed mid-way or completed (cached per tree)."""
    key = (str(tree), kind)
    if key not in _templates:
        data = scratch / f"template-{len(_templates)}-{kind}"
        if kind == "killed":
            code, _, err, _, _ = run_child(tree, [sys.executable, "-c", _KILL_SCRIPT, str(QUICKSTART), str(data)],
                                           scratch, 300)
        else:
            code, _, err = pianobot(tree, ["sweep", str(QUICKSTART), "--data", str(data), "--no-progress"], scratch, 300)
        if code != 0:
            raise RuntimeError(f"making the {kind} run failed ({code}): {err[-500:]}")
        _templates[key] = data
    return _templates[key]


def _run_copy(tree: Path, folder: Path, kind: str) -> tuple[Path, Path]:
    data = folder / "data"
    shutil.copytree(_template(tree, kind, folder.parent), data)
    (run,) = sorted((data / "runs").iterdir())
    return data, run


def _truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _first(run: Path, table: str) -> Path:
    return sorted((run / ("samples" if table == "samples" else "parts")).glob(f"{table}-*.parquet"))[0]


def damaged(kind: str, command: str) -> Callable[[Path, Path], list[str]]:
    """A quickstart run damaged one way, then `command` (resume, show, report, list) on it."""

    def build(tree: Path, folder: Path) -> list[str]:
        source = "completed" if kind == "truncated compacted trials.parquet" else "killed"
        data, run = _run_copy(tree, folder, source)
        if kind == "truncated samples part":
            _truncate(_first(run, "samples"))
        elif kind == "truncated trials part":
            _truncate(_first(run, "trials"))
        elif kind == "empty trials part":
            _first(run, "trials").write_bytes(b"")
        elif kind == "truncated plan.parquet":
            _truncate(run / "plan.parquet")
        elif kind == "garbled run.json":
            (run / "run.json").write_text('{"run_id": "x", "status": "runn')
        elif kind == "truncated compacted trials.parquet":
            _truncate(run / "trials.parquet")
        args = {
            "resume": ["sweep", str(QUICKSTART), "--resume", run.name, "--no-progress"],
            "show": ["runs", "show", run.name],
            "report": ["report", run.name, "--out", str(folder / "report.html")],
            "list": ["runs", "--json"],
        }[command]
        return [*args, "--data", str(data)]

    return build


def _lists_damaged(folder: Path, outcome: Outcome) -> str | None:
    try:
        runs = json.loads(outcome.stdout)
    except ValueError:
        return "no JSON list"
    if not runs:
        return "no run listed"
    return None if any(r.get("status") == "damaged" for r in runs) else (
        f"listed as {', '.join(str(r.get('status')) for r in runs)}, not damaged")


# ---- spec, rig and option cases -------------------------------------------------------------

def _write(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.write_text(text)
    return path


def _data(folder: Path) -> Path:
    data = folder / "data"
    data.mkdir(exist_ok=True)
    return data


def alias_bomb(levels: int) -> Callable[[Path, Path], list[str]]:
    def build(tree: Path, folder: Path) -> list[str]:
        lines = ["name: bomb", "finger: soft", "x0: &a0 [1, 1, 1, 1, 1, 1, 1, 1, 1, 1]"]
        lines += [f"x{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 10) + "]" for i in range(1, levels + 1)]
        lines.append("sweep: {mode: grid, params: {down_velocity_mps: [0.02], depth_m: [0.03]}}")
        spec = _write(folder, "bomb.yaml", "\n".join(lines) + "\n")
        return ["sweep", str(spec), "--dry-run", "--data", str(_data(folder))]

    return build


def spec_with(body: str, *, dry_run: bool = True) -> Callable[[Path, Path], list[str]]:
    def build(tree: Path, folder: Path) -> list[str]:
        text = f"name: case\nfinger: soft\nrig: {SIM_RIG}\n{body}"
        spec = _write(folder, "spec.yaml", text)
        return ["sweep", str(spec), *(["--dry-run"] if dry_run else []), "--data", str(_data(folder))]

    return build


def grid_of(levels: int) -> Callable[[Path, Path], list[str]]:
    params = {"vacuum_kpa": (-80, -1), "down_velocity_mps": (0.01, 0.06),
              "acceleration_mps2": (0.2, 2.0), "depth_m": (0.02, 0.035)}
    body = "sweep:\n  mode: grid\n  params:\n" + "".join(
        f"    {name}: {{start: {lo}, stop: {hi}, num: {levels}}}\n" for name, (lo, hi) in params.items())
    return spec_with(body)


def rig_with(text: str) -> Callable[[Path, Path], list[str]]:
    def build(tree: Path, folder: Path) -> list[str]:
        rig = _write(folder, "rig.yaml", text)
        return ["sweep", str(QUICKSTART), "--rig", str(rig), "--no-progress", "--data", str(_data(folder))]

    return build


def data_is_a_file(tree: Path, folder: Path) -> list[str]:
    return ["sweep", str(QUICKSTART), "--data", str(_write(folder, "data", "a file"))]


def seed(value: str) -> Callable[[Path, Path], list[str]]:
    def build(tree: Path, folder: Path) -> list[str]:
        return ["sweep", str(QUICKSTART), "--seed", value, "--no-progress", "--data", str(_data(folder))]

    return build


def resume_on_another_rig(tree: Path, folder: Path) -> list[str]:
    data, run = _run_copy(tree, folder, "killed")
    # The quickstart ran on the built-in `sim` rig; this one waits longer between presses.
    other = _write(folder, "other-rig.yaml", "kind: sim\nsettle_s:\n  between_presses_s: 0.9\n")
    return ["sweep", str(QUICKSTART), "--resume", run.name, "--rig", str(other), "--no-progress",
            "--data", str(data)]


def identify_out_folder(tree: Path, folder: Path) -> list[str]:
    data, run = _run_copy(tree, folder, "completed")
    out = folder / "model-out"
    out.mkdir()
    return ["identify", run.name, "--data", str(data), "--out", str(out)]


# ---- imported files ----------------------------------------------------------------------------

LOG = FIXTURES / "data" / "soft" / "ctrl_midi" / "soft_60_angle_45.txt"
FORCE = FIXTURES / "data" / "soft" / "force" / "P60A45.txt"
TAKE = FIXTURES / "zzz" / "zzz40.csv"


def force_with(reading: str) -> Callable[[Path, Path], list[str]]:
    def build(tree: Path, folder: Path) -> list[str]:
        lines = FORCE.read_text().splitlines()
        middle = len(lines) // 2
        capture = _write(folder, "capture.txt",
                         "\n".join([*lines[:middle], f"Analog reading = {reading}", *lines[middle:]]) + "\n")
        return ["import", "force-log", str(capture), "--json", "--data", str(_data(folder))]

    return build


def _force_sane(folder: Path, outcome: Outcome) -> str | None:
    try:
        result = json.loads(outcome.stdout)
        run = next((folder / "data" / "runs").iterdir())
        import pyarrow.parquet as pq

        peaks = pq.read_table(run / "trials.parquet", columns=["peak_force_n"]).column(0).to_pylist()
    except (ValueError, StopIteration, OSError) as exc:
        return f"no result ({type(exc).__name__})"
    if max(peaks) > 100:
        return f"peak force {max(peaks):.3g} N stored"
    skipped = result.get("skipped_lines") or []
    return None if skipped else "the absurd reading was not reported as a skipped line"


def gain_nan(tree: Path, folder: Path) -> list[str]:
    return ["import", "force-log", str(FORCE), "--gain-n", "nan", "--data", str(_data(folder))]


def mocap_one_line(tree: Path, folder: Path) -> list[str]:
    take = folder / "oneline.csv"
    with open(take, "w") as handle:
        handle.write("Format Version,1.21,Take Name,x," + "A" * 50_000_000)
    return ["import", "mocap", str(take), "--data", str(_data(folder))]


def mocap_reversed(tree: Path, folder: Path) -> list[str]:
    text = TAKE.read_text().splitlines()
    header = next(i for i, line in enumerate(text) if line.startswith("Frame,"))
    take = _write(folder, "reversed.csv", "\n".join(text[: header + 1] + text[header + 1:][::-1]) + "\n")
    return ["import", "mocap", str(take), "--data", str(_data(folder))]


def mocap_min_coverage_nan(tree: Path, folder: Path) -> list[str]:
    return ["import", "mocap", str(TAKE), "--min-coverage", "nan", "--data", str(_data(folder))]


def log_with_bom(tree: Path, folder: Path) -> list[str]:
    log = folder / "bom.txt"
    log.write_bytes(b"\xef\xbb\xbf" + LOG.read_bytes())
    return ["import", "keystroke-log", str(log), "--json", "--data", str(_data(folder))]


def _all_135_trials(folder: Path, outcome: Outcome) -> str | None:
    try:
        trials = json.loads(outcome.stdout)["trials"]
    except (ValueError, KeyError, TypeError):
        return "no result"
    return None if trials == 135 else f"{trials} trials, the plain file gives 135"


def long_log(lines: int) -> Callable[[Path, Path], list[str]]:
    """The study's log repeated to `lines` lines as ONE clock session: each repetition's MIDI
    timestamps are shifted past the previous one's, so no line starts a new session (a session
    restart every 135 lines would hide a quadratic assignment)."""

    def build(tree: Path, folder: Path) -> list[str]:
        source = [line for line in LOG.read_text().splitlines() if line.strip()]
        stamp = re.compile(r"\], (\d+)\]")
        span_ms = max(int(t) for line in source for t in stamp.findall(line)) + 5_000
        with open(folder / "long.txt", "w") as out:
            for i in range(lines):
                shift = (i // len(source)) * span_ms
                line = source[i % len(source)]
                out.write(stamp.sub(lambda m, shift=shift: f"], {int(m.group(1)) + shift}]", line) + "\n")
        return ["import", "keystroke-log", str(folder / "long.txt"), "--json", "--data", str(_data(folder))]

    return build


def _imported(folder: Path, outcome: Outcome) -> str | None:
    try:
        json.loads(outcome.stdout)
    except ValueError:
        return "no JSON result"
    return None


def _write_song(path: Path, n_notes: int) -> None:
    """Eighth notes at 120 bpm over two octaves from C3, velocities 40..99 (mido writes it)."""
    import mido

    track = mido.MidiTrack()
    for k in range(n_notes):
        note = 48 + k % 24
        track.append(mido.Message("note_on", note=note, velocity=40 + k % 60, time=0 if k == 0 else 120))
        track.append(mido.Message("note_off", note=note, velocity=0, time=100))
    song = mido.MidiFile(ticks_per_beat=480)
    song.tracks.append(track)
    song.save(path)


def play_dry_run(notes: int) -> Callable[[Path, Path], list[str]]:
    def build(tree: Path, folder: Path) -> list[str]:
        song = folder / "song.mid"
        _write_song(song, notes)
        return ["play", str(song), "--dry-run", "--data", str(_data(folder))]

    return build


def _played(folder: Path, outcome: Outcome) -> str | None:
    return None if outcome.stdout.strip() else "no plan printed"


CASES: list[Case] = [
    Case("yaml-bomb-8", "1", "YAML alias bomb, 8 levels (`sweep --dry-run`)", alias_bomb(8)),
    Case("yaml-bomb-9", "1", "YAML alias bomb, 9 levels (`sweep --dry-run`)", alias_bomb(9)),
    *[
        Case(f"damaged-{kind.replace(' ', '-').replace('.', '-')}-{command}", "2",
             f"{kind}: `{'sweep --resume' if command == 'resume' else 'runs show' if command == 'show' else command}`",
             damaged(kind, command))
        for kind, commands in [
            ("truncated samples part", ["resume"]),
            ("truncated trials part", ["resume", "show", "report"]),
            ("empty trials part", ["resume"]),
            ("truncated plan.parquet", ["resume", "show"]),
            ("garbled run.json", ["resume", "show"]),
            ("truncated compacted trials.parquet", ["show", "report"]),
        ]
        for command in commands
    ],
    Case("damaged-listed", "2", "`pianobot runs` with a damaged run (truncated trials part)",
         damaged("truncated trials part", "list"), expect="ok", check=_lists_damaged),
    Case("resume-other-rig", "4", "resume with another `--rig` file (other settle time)", resume_on_another_rig),
    Case("grid-1e9", "5", "10⁹-trial grid (`sweep --dry-run`)", grid_of(178)),
    Case("grid-1e7", "5", "10⁷-trial grid (`sweep --dry-run`)", grid_of(57)),
    Case("log-20k", "5", "keystroke log of 20,000 lines (import)", long_log(20_000), expect="ok",
         check=_imported, timeout_s=60, needs_fixtures=True),
    Case("log-300k", "5", "keystroke log of 300,000 lines (import)", long_log(300_000), expect="ok",
         check=_imported, timeout_s=120, needs_fixtures=True),
    Case("play-20k", "5", "`play --dry-run`, 20,000 notes", play_dry_run(20_000), expect="ok",
         check=_played, timeout_s=120),
    Case("spec-nan", "6", "NaN in a spec (`down_velocity_mps: [.nan]`)",
         spec_with("sweep:\n  mode: grid\n  params:\n    down_velocity_mps: [.nan]\n    depth_m: [0.03]\n")),
    Case("rig-world-nan", "6", "NaN in a rig file's simulated world (`world.msd.c1_nspm: .nan`, `sweep`)",
         rig_with("kind: sim\nworld: {msd: {c1_nspm: .nan}}\n")),
    Case("rig-envelope-inf", "6", "inf in a rig file's envelope (`depth_m: [0.02, .inf]`, `sweep`)",
         rig_with("kind: sim\nenvelope: {soft: {depth_m: [0.02, .inf]}}\n")),
    Case("data-is-file", "6", "`--data` names a file (`sweep`)", data_is_a_file),
    Case("identify-out-dir", "6", "`identify --out DIR`", identify_out_folder),
    Case("force-100k-digits", "6", "force reading of 100,000 digits (import)", force_with("9" * 100_000),
         expect="ok", check=_force_sane, needs_fixtures=True),
    Case("mocap-50mb-line", "6", "50 MB single-line mocap file (import)", mocap_one_line),
    Case("seed-negative", "6", "`sweep --seed -5`", seed("-5")),
    Case("spec-bool", "7", "`acceleration_mps2: true` in a spec", spec_with(
        "sweep:\n  mode: grid\n  params:\n    down_velocity_mps: [0.02]\n    depth_m: [0.03]\n"
        "    acceleration_mps2: [true]\n")),
    Case("spec-string-number", "7", "`\"1.0\"` (a string) as a number in a spec", spec_with(
        "sweep:\n  mode: grid\n  params:\n    down_velocity_mps: [0.02]\n    depth_m: [0.03]\n"
        "    acceleration_mps2: [\"1.0\"]\n")),
    Case("force-1e40", "7", "force reading of 1e40 (import)", force_with("1" + "0" * 40), expect="ok",
         check=_force_sane, needs_fixtures=True),
    Case("gain-nan", "7", "`import force-log --gain-n nan`", gain_nan, needs_fixtures=True),
    Case("mocap-reversed", "7", "time-reversed mocap frames (import)", mocap_reversed, needs_fixtures=True),
    Case("min-coverage-nan", "7", "`import mocap --min-coverage nan`", mocap_min_coverage_nan, needs_fixtures=True),
    Case("log-bom", "7", "UTF-8 BOM before a keystroke log (import)", log_with_bom, expect="ok",
         check=_all_135_trials, needs_fixtures=True),
]


def judge(case: Case, folder: Path, outcome: Outcome) -> tuple[bool, str]:
    """(as promised?, why not)."""
    if outcome.code is None:
        return False, f"timed out after {outcome.seconds:.0f} s"
    if case.expect == "refused":
        problems = []
        if outcome.code != 2:
            problems.append(f"exit {outcome.code}")
        if outcome.traceback:
            problems.append("traceback")
        elif len(outcome.stderr_lines) != 1:
            problems.append(f"{len(outcome.stderr_lines)} stderr lines")
        if outcome.changed:
            problems.append(f"changed {', '.join(outcome.changed[:3])}")
        return not problems, "; ".join(problems)
    if outcome.code != 0 or outcome.traceback:
        return False, f"exit {outcome.code}" + (" with a traceback" if outcome.traceback else "")
    wrong = case.check(folder, outcome) if case.check else None
    return wrong is None, wrong or ""


def run_case(case: Case, tree: Path, scratch: Path) -> dict[str, Any]:
    folder = scratch / case.key
    folder.mkdir()
    argv = case.build(tree, folder)
    before = _digest(folder)
    code, out, err, seconds, rss = run_child(tree, [sys.executable, "-m", "pianobot", *argv], folder,
                                             case.timeout_s)
    after = _digest(folder)
    changed = sorted(k for k in set(before) | set(after) if before.get(k) != after.get(k))
    lines = [line for line in err.splitlines() if line.strip()]
    outcome = Outcome(code, lines, out, seconds, rss, changed, "Traceback (most recent call last)" in err)
    ok, why = judge(case, folder, outcome)
    shutil.rmtree(folder, ignore_errors=True)
    line = outcome.line().replace(f"{folder}/", "").replace(str(folder), ".")[:160]  # no temp paths
    return {"code": code, "stderr_lines": len(lines), "line": line, "traceback": outcome.traceback,
            "changed": changed[:10], "seconds": round(seconds, 3), "peak_rss_mib": round(rss, 1),
            "as_promised": ok, "why_not": why}


def _cell(result: dict[str, Any]) -> str:
    if result.get("skipped"):
        return "skipped (no fixtures)"
    mark = "✓" if result["as_promised"] else "✗"
    code = "timeout" if result["code"] is None else f"exit {result['code']}"
    text = f"{mark} {code}, {result['seconds']:.1f} s, {result['peak_rss_mib']:.0f} MiB"
    if not result["as_promised"]:
        text += f": {result['why_not']}"
    line = str(result["line"]).replace("|", "\\|")
    return f"{text} — `{line[:110]}`" if line else text


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tree", action="append", default=[], metavar="NAME=PATH",
                        help="a source tree to run the cases against (default: this one, as 'after')")
    parser.add_argument("--only", action="append", default=[], help="run only cases whose key starts so")
    parser.add_argument("--out", type=Path, default=RESULTS / "robustness_cases.json")
    parser.add_argument("--update", action="store_true",
                        help="keep the other cases' and trees' results already in --out")
    args = parser.parse_args()
    trees = [(n, Path(p).resolve()) for n, p in (t.split("=", 1) for t in args.tree)] or [("after", REPO)]
    cases = [c for c in CASES if not args.only or any(c.key.startswith(o) for o in args.only)]
    have_fixtures = FIXTURES.is_dir()
    results: dict[str, dict[str, Any]] = {c.key: {} for c in cases}
    previous: dict[str, Any] = {}
    if args.update and args.out.is_file():
        previous = json.loads(args.out.read_text())
        for entry in previous.get("cases", []):
            if entry["key"] in {c.key for c in CASES}:
                results.setdefault(entry["key"], {}).update(entry["results"])
    shown = [c for c in CASES if c.key in results]
    scratch_root = Path(tempfile.mkdtemp(prefix="pianobot-cases-"))
    try:
        for name, tree in trees:
            scratch = scratch_root / name
            scratch.mkdir()
            for case in cases:
                if case.needs_fixtures and not have_fixtures:
                    results[case.key][name] = {"skipped": True}
                    continue
                result = run_case(case, tree, scratch)
                results[case.key][name] = result
                print(f"{name:8s} {case.key:48s} {_cell(result)[:150]}", file=sys.stderr, flush=True)
    finally:
        shutil.rmtree(scratch_root, ignore_errors=True)
    all_trees = {**previous.get("trees", {}), **{n: str(p) for n, p in trees}}
    names = list(all_trees)
    payload = {"trees": all_trees, "memory_cap_gib": MEMORY_CAP_BYTES / 2**30,
               "load_average": os.getloadavg(),
               "cases": [{"key": c.key, "point": c.point, "what": c.what, "expect": c.expect,
                          "results": results[c.key]} for c in shown]}
    ran = {n: [c for c in shown if n in results[c.key] and not results[c.key][n].get("skipped")] for n in names}
    totals = {n: sum(bool(results[c.key][n].get("as_promised")) for c in ran[n]) for n in names}
    payload["as_promised"] = {n: f"{totals[n]}/{len(ran[n])}" for n in names}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(_anonymous(json.dumps(payload, indent=2), all_trees) + "\n")
    table = ["| # | case | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]
    for c in shown:
        table.append(f"| {c.point} | {c.what} | "
                     + " | ".join(_cell(results[c.key][n]) if n in results[c.key] else "-" for n in names) + " |")
    table.append("| | as promised | " + " | ".join(payload["as_promised"][n] for n in names) + " |")
    text = _anonymous("\n".join(table), all_trees)
    args.out.with_suffix(".md").write_text(text + "\n")
    print(text)


def _anonymous(text: str, trees: dict[str, str]) -> str:
    """No path of this machine in the results: trees, the interpreter and the repo by name."""
    places = [(path, f"<{name}>") for name, path in trees.items() if path.startswith("/")]
    places += [(sys.prefix, "<venv>"), (str(REPO), "<repo>"), (str(REPO.parent), "<repo>/..")]
    for path, label in sorted(places, key=lambda p: -len(p[0])):
        text = text.replace(path, label)
    # a case folder cut short by the line limit
    return re.sub(re.escape(tempfile.gettempdir()) + r"/pianobot-cases-[^\s`'\"|]*", "<case folder>", text)


if __name__ == "__main__":
    main()
