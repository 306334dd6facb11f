"""Property-based fuzzing of every reader of user files and stored data.

The property, everywhere: the reader succeeds, or refuses with an InputError whose message is
one line; through the CLI that is exit 2 with one stderr line; and on a refusal the data
folder is exactly as it was. Generated inputs include NaN, ±inf, numbers past float range,
huge integers, bools and text where numbers belong, YAML anchors and aliases (also aliases that
multiply), deep nesting, truncated and bit-flipped files, and journals cut at any byte.
"""

from __future__ import annotations

import dataclasses
import json
import math
import shutil
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from pianobot.errors import InputError
from robustness.harness import QUICKSTART, cli, only_run, tree_digest

FUZZ = settings(max_examples=60, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
FEW = settings(max_examples=12, deadline=None,
               suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
SONGS = Path(__file__).resolve().parents[2] / "experiments" / "songs"


def _one_line(exc: InputError) -> None:
    assert "\n" not in str(exc) and str(exc).strip(), repr(str(exc))


def _assert_finite(value: Any) -> None:
    """Every float in a nested structure of dicts, lists and tuples is finite."""
    if isinstance(value, float):
        assert math.isfinite(value)
    elif isinstance(value, dict):
        for v in value.values():
            _assert_finite(v)
    elif isinstance(value, list | tuple):
        for v in value:
            _assert_finite(v)


# --- values a hostile file may hold ---------------------------------------------------------

HOSTILE_SCALARS = st.one_of(
    st.just(math.nan), st.just(math.inf), st.just(-math.inf), st.just(True), st.just(False),
    st.just(None), st.text(max_size=12), st.integers(min_value=-(10**30), max_value=10**30),
    st.floats(allow_nan=True, allow_infinity=True), st.just(10**400), st.just("1e400"),
    st.just("nan"), st.just(""), st.just([]), st.just({}),
)


def _yaml_scalar(value: Any) -> str:
    """A scalar as YAML text (PyYAML's dump of NaN/inf, and raw text for the odd ones)."""
    if isinstance(value, float) and math.isnan(value):
        return ".nan"
    if isinstance(value, float) and math.isinf(value):
        return ".inf" if value > 0 else "-.inf"
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > 10**300:
        return str(value)
    return yaml.safe_dump(value, default_flow_style=True).strip().removesuffix("\n...").strip()


SPEC_PATHS = [
    ("name",), ("finger",), ("note",), ("rig",), ("record",),
    ("sweep", "mode"), ("sweep", "seed"), ("sweep", "repeats"), ("sweep", "order"), ("sweep", "samples"),
    ("sweep", "params", "down_velocity_mps"), ("sweep", "params", "depth_m"),
    ("sweep", "params", "vacuum_kpa"), ("sweep", "params", "down_velocity_mps", "num"),
    ("sweep", "fixed", "acceleration_mps2"), ("sweep", "fixed", "hold_s"), ("sweep", "block_by"),
]


def _base_spec() -> dict[str, Any]:
    return {"name": "fuzz", "finger": "soft", "sweep": {
        "mode": "grid", "params": {"down_velocity_mps": {"start": 0.01, "stop": 0.05, "num": 3},
                                   "depth_m": [0.02, 0.03]},
        "fixed": {"acceleration_mps2": 0.5}}}


def _set(doc: dict[str, Any], path: tuple[str, ...], value: Any) -> None:
    node = doc
    for key in path[:-1]:
        if not isinstance(node.get(key), dict):
            node[key] = {}
        node = node[key]
    node[path[-1]] = value


def _yaml(value: Any, indent: int = 0) -> str:
    """Block YAML of nested dicts/lists with scalars written by `_yaml_scalar`."""
    pad = " " * indent
    if isinstance(value, dict) and value:
        return "\n" + "\n".join(f"{pad}{k}: {_yaml(v, indent + 2).lstrip(' ') if not isinstance(v, dict) or not v else _yaml(v, indent + 2)}"
                                for k, v in value.items())
    if isinstance(value, list) and value:
        return "[" + ", ".join(_yaml(v).strip() for v in value) + "]"
    return _yaml_scalar(value)


@st.composite
def hostile_specs(draw: st.DrawFn) -> str:
    doc = _base_spec()
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(SPEC_PATHS))
        value = draw(st.one_of(HOSTILE_SCALARS, st.lists(HOSTILE_SCALARS, max_size=4)))
        _set(doc, path, value)
    text = _yaml(doc).lstrip("\n") + "\n"
    extra = draw(st.sampled_from(["none", "anchors", "bomb", "deep", "self-alias"]))
    if extra == "anchors":  # a shared value used twice (legal YAML, and harmless)
        text = "shared: &s [0.02, 0.03]\n" + text.replace("depth_m: [0.02, 0.03]", "depth_m: *s")
    elif extra == "bomb":
        width, levels = draw(st.integers(2, 12)), draw(st.integers(2, 9))
        bomb = ["b0: &b0 [" + ", ".join(["1"] * width) + "]"]
        bomb += [f"b{i}: &b{i} [" + ", ".join([f"*b{i - 1}"] * width) + "]" for i in range(1, levels)]
        text = "\n".join(bomb) + "\n" + text
    elif extra == "deep":
        depth = draw(st.integers(10, 3000))
        text += "deep: " + "[" * depth + "]" * depth + "\n"
    elif extra == "self-alias":
        text += "loop: &loop {a: *loop}\n"
    return text


@FUZZ
@given(text=hostile_specs())
def test_the_spec_loader_loads_or_refuses_in_one_line(text: str, tmp_path_factory: pytest.TempPathFactory) -> None:
    from pianobot.plan import expand
    from pianobot.spec import load_spec

    spec_file = tmp_path_factory.mktemp("spec") / "fuzz.yaml"
    spec_file.write_text(text)
    try:
        spec = load_spec(spec_file)
        trials = expand(spec)
    except InputError as exc:
        _one_line(exc)
        return
    # What loads plans physical trials, in run order, the same each time.
    assert [t.index for t in trials] == list(range(len(trials)))
    _assert_finite([dataclasses.asdict(t) for t in trials])
    assert expand(spec) == trials


RIG_PATHS = [("kind",), ("seed",), ("realtime",), ("settle_s", "between_presses_s"),
             ("settle_s", "after_vacuum_change_s"), ("retry", "max_attempts"), ("retry", "backoff_s"),
             ("travel", "velocity_mps"), ("faults", "midi_loss_prob"), ("world", "msd", "c1_nspm"),
             ("world", "piano", "full_scale_speed_mps"), ("world", "preset"),
             ("envelope", "soft", "depth_m"), ("keyboard", "offsets_m"), ("keyboard", "white_key_pitch_m")]


@FUZZ
@given(changes=st.lists(st.tuples(st.sampled_from(RIG_PATHS),
                                  st.one_of(HOSTILE_SCALARS, st.lists(HOSTILE_SCALARS, max_size=3))),
                        min_size=1, max_size=3))
def test_the_rig_loader_loads_or_refuses_in_one_line(changes: list[tuple[tuple[str, ...], Any]],
                                                     tmp_path_factory: pytest.TempPathFactory) -> None:
    from pianobot.spec import load_rig

    doc: dict[str, Any] = {"kind": "sim"}
    for path, value in changes:
        _set(doc, path, value)
    rig_file = tmp_path_factory.mktemp("rig") / "rig.yaml"
    rig_file.write_text(_yaml(doc).lstrip("\n") + "\n")
    try:
        rig = load_rig(rig_file)
    except InputError as exc:
        _one_line(exc)
        return
    _assert_finite(rig.model_dump())  # what loads is physical: every number finite


@FEW
@given(text=hostile_specs())
def test_the_cli_refuses_a_hostile_spec_in_one_line_and_stores_nothing(
    text: str, completed_run: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    spec_file = completed_run.parent / "fuzz.yaml"
    spec_file.write_text(text)
    before = tree_digest(completed_run)
    code, _, err = cli(["sweep", spec_file, "--dry-run", "--data", completed_run], capsys, monkeypatch)
    assert code in (0, 2), err
    if code == 2:
        assert len(err.strip().splitlines()) == 1 and err.startswith("error: ")
    assert tree_digest(completed_run) == before


# --- MIDI songs -----------------------------------------------------------------------------

@FUZZ
@given(data=st.data())
def test_the_midi_reader_reads_or_refuses_in_one_line(data: st.DataObject,
                                                      tmp_path_factory: pytest.TempPathFactory) -> None:
    from pianobot.io.midifile import read_song

    source = data.draw(st.sampled_from(sorted(SONGS.glob("*.mid"))))
    raw = bytearray(source.read_bytes())
    how = data.draw(st.sampled_from(["flip", "truncate", "insert", "header", "random"]))
    if how == "flip":
        for _ in range(data.draw(st.integers(1, 20))):
            i = data.draw(st.integers(0, len(raw) - 1))
            raw[i] ^= data.draw(st.integers(1, 255))
    elif how == "truncate":
        raw = raw[: data.draw(st.integers(0, len(raw) - 1))]
    elif how == "insert":
        i = data.draw(st.integers(0, len(raw)))
        raw[i:i] = data.draw(st.binary(min_size=1, max_size=64))
    elif how == "header":  # format, track count, division: the fields readers trust most
        raw[8:14] = data.draw(st.binary(min_size=6, max_size=6))
    else:
        raw = bytearray(b"MThd" + data.draw(st.binary(max_size=300)))
    song_file = tmp_path_factory.mktemp("song") / "fuzz.mid"
    song_file.write_bytes(bytes(raw))
    try:
        song = read_song(song_file)
    except InputError as exc:
        _one_line(exc)
        return
    for note in song.notes:
        assert math.isfinite(note.onset_s) and note.offset_s > note.onset_s
        assert 21 <= note.pitch <= 108 and 0 <= note.velocity <= 127


# --- model and predictor files -------------------------------------------------------------

def _mutate_json(value: Any, data: st.DataObject, depth: int = 0) -> Any:
    if isinstance(value, dict) and value and depth < 4:
        key = data.draw(st.sampled_from(sorted(value)))
        out = dict(value)
        action = data.draw(st.sampled_from(["replace", "recurse", "delete", "add"]))
        if action == "delete":
            del out[key]
        elif action == "add":
            out[data.draw(st.text(max_size=8))] = data.draw(HOSTILE_SCALARS)
        elif action == "recurse":
            out[key] = _mutate_json(value[key], data, depth + 1)
        else:
            out[key] = data.draw(HOSTILE_SCALARS)
        return out
    if isinstance(value, list) and value and depth < 4:
        out_list = list(value)
        i = data.draw(st.integers(0, len(value) - 1))
        out_list[i] = _mutate_json(value[i], data, depth + 1)
        return out_list
    return data.draw(HOSTILE_SCALARS)


@FUZZ
@given(data=st.data())
def test_model_and_predictor_files_load_or_refuse_in_one_line(
    data: st.DataObject, tmp_path_factory: pytest.TempPathFactory,
) -> None:
    from pianobot.analysis.learn.files import load_predictor
    from pianobot.physics.model import KeystrokeModel, read_model_file, save_model

    folder = tmp_path_factory.mktemp("model")
    good = save_model(KeystrokeModel.study().with_effect("keybed"), folder / "good.json",
                      intervals={"k1_a_npm": {"value": 75.0, "ci95": [70.0, 80.0]}})
    payload = json.loads(good.read_text())
    mutated = _mutate_json(payload, data)
    path = folder / "fuzz.json"
    as_text = json.dumps(mutated, allow_nan=True)
    if data.draw(st.booleans()):
        as_text = as_text[: data.draw(st.integers(0, len(as_text)))]
    path.write_text(as_text)
    try:
        model_file = read_model_file(path)
    except InputError as exc:
        _one_line(exc)
    else:  # what loads is a physical model: every number finite, and it saves again
        _assert_finite(model_file.model.to_dict())
        again = read_model_file(save_model(model_file.model, folder / "again.json"))
        assert again.model.to_dict() == model_file.model.to_dict()
    try:
        predictor = load_predictor(path)
    except InputError as exc:
        _one_line(exc)
    else:
        assert callable(predictor.predict)


@FUZZ
@given(sidecar=st.fixed_dictionaries({
    "schema": st.just("pianobot.predictor/1"),
    "estimator_file": st.one_of(st.text(max_size=20), HOSTILE_SCALARS, st.just("../../x"), st.just("a\x00b")),
    "estimator_sha256": st.one_of(st.text(max_size=64), HOSTILE_SCALARS),
}))
def test_a_learned_predictor_sidecar_loads_or_refuses_in_one_line(
    sidecar: dict[str, Any], tmp_path_factory: pytest.TempPathFactory,
) -> None:
    from pianobot.analysis.learn.files import load_predictor

    path = tmp_path_factory.mktemp("predictor") / "predictor.json"
    path.write_text(json.dumps(sidecar, allow_nan=True))
    with pytest.raises(InputError) as refused:
        load_predictor(path)
    _one_line(refused.value)


# --- stored runs ---------------------------------------------------------------------------

STORE_FILES = ["plan.parquet", "run.json", "journal.jsonl", "parts/trials", "samples/samples", "parts/midi"]


def _target(run: Path, name: str, pick: int) -> Path:
    if "/" in name:
        folder, table = name.split("/")
        parts = sorted((run / folder).glob(table + "-*.parquet"))
        assume(parts)
        return parts[pick % len(parts)]
    return run / name


@FEW
@given(name=st.sampled_from(STORE_FILES), pick=st.integers(0, 10), cut=st.floats(0.0, 0.999),
       flip=st.booleans())
def test_a_damaged_run_is_read_or_refused_in_one_line_and_never_changed(
    name: str, pick: int, cut: float, flip: bool, templates: dict[str, Path],
    tmp_path_factory: pytest.TempPathFactory, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    data = tmp_path_factory.mktemp("store") / "data"
    shutil.copytree(templates["killed"], data)
    run = only_run(data)
    target = _target(run, name, pick)
    raw = bytearray(target.read_bytes())
    if flip and raw:
        raw[int(cut * len(raw))] ^= 0x5A
    else:
        raw = raw[: int(cut * len(raw))]
    target.write_bytes(bytes(raw))
    for args in (["runs", "show", run.name], ["runs"], ["runs", "check", run.name]):
        before = tree_digest(data)
        code, _, err = cli([*args, "--data", data], capsys, monkeypatch)
        assert "Traceback" not in err
        if args[-1] == run.name and args[1] == "check":
            assert code in (0, 1)
        else:
            assert code in (0, 2)
        if code == 2:
            assert len(err.strip().splitlines()) == 1 and err.startswith("error: ")
        assert tree_digest(data) == before


@FEW
@given(cut=st.floats(0.0, 1.0), garble=st.booleans())
def test_a_torn_journal_still_resumes_to_every_trial_exactly_once(
    cut: float, garble: bool, templates: dict[str, Path], tmp_path_factory: pytest.TempPathFactory,
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
) -> None:
    from pianobot.store import load_run

    data = tmp_path_factory.mktemp("journal") / "data"
    shutil.copytree(templates["killed"], data)
    run = only_run(data)
    journal = run / "journal.jsonl"
    raw = journal.read_bytes()
    at = int(cut * len(raw))
    journal.write_bytes(raw[:at] + (b"\x00garbage}\n" + raw[at:] if garble else b""))
    code, _, err = cli(["sweep", "--resume", run.name, "--data", data, "--json", "--no-progress"],
                       capsys, monkeypatch)
    assert code == 0, err
    final = load_run(run.name, data)
    trials = final.trials
    assert trials["trial_id"].is_unique and sorted(trials["trial_id"]) == sorted(final.plan["trial_id"])


def test_quickstart_exists() -> None:
    assert QUICKSTART.is_file()
