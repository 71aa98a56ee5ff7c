"""Fuzz suite (issue 21): hypothesis-generated G-code, TOML files, damaged recordings and CLI
arguments through the in-process CLI.

Property of every run: exit 0, or exit 2 with one line ``millsense: error: ...`` naming the
input (a file, key or option the run was given); never a traceback; the inputs' checksums
unchanged; within a time and memory ceiling. Derandomized (the same examples on every run, CI
stable) with a small ``max_examples`` per target to keep the suite near 2 minutes of
``make test`` (decision 0944 "Fuzz suite").
"""

from __future__ import annotations

import hashlib
import json
import math
import resource
import shutil
import tempfile
import time
import tomllib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from cli_run import run_cli
from millsense.simulator.machine_file import simulator_machine_path

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "examples" / "demo_part"
DATA = ROOT / "src" / "millsense" / "data"
#: The simulator's own machine file: estimate runs on it here to fuzz the recording, not the
#: identification (the nameplate preset has no friction or modes, decision 0991)
SIM_QUASER = str(simulator_machine_path("quaser-ux600"))

#: Wall-time ceiling of one CLI run, s (the slowest target, estimate, takes ~3 s).
TIME_CEILING_S = 60.0
#: Peak resident memory ceiling of the test process, bytes.
MEMORY_CEILING_B = 4 * 2**30

FUZZ = settings(
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
    print_blob=True,
    # no shrinking: one example takes seconds; the first failing example is reported as found
    phases=[Phase.explicit, Phase.reuse, Phase.generate],
)

#: Enters the demo stock 1 mm after the start of its feed move (0.1 mm/tooth at 6000 rev/min).
SMALL_PROGRAM = "%\nG21 G90 G94 G17\nS6000 M3\nG0 X-11 Y5 Z-1\nG1 X20 F1200\nM30\n%\n"


@contextmanager
def _tmpdir() -> Iterator[Path]:
    d = tempfile.mkdtemp(prefix="millsense-fuzz-")
    try:
        yield Path(d)
    finally:
        shutil.rmtree(d, ignore_errors=True)


def _sha(paths: list[Path]) -> dict[str, str]:
    return {str(p): hashlib.sha256(p.read_bytes()).hexdigest() for p in paths if p.is_file()}


def _check(
    args: list[str],
    inputs: list[Path],
    names: list[str],
    capsys: pytest.CaptureFixture[str],
) -> int:
    """Run ``millsense ARGS`` and assert the fuzz property; returns the exit status."""
    before = _sha(inputs)
    t0 = time.perf_counter()
    code, _, err = run_cli(args, capsys)
    wall = time.perf_counter() - t0
    assert "Traceback" not in err, err
    assert code in (0, 2), f"exit {code}: {err}"
    if code == 2:
        lines = [ln for ln in err.strip().splitlines() if ln.startswith("millsense: error: ")]
        others = [
            ln
            for ln in err.strip().splitlines()
            if ln.strip() and not ln.startswith(("millsense: warning: ", "millsense: note: "))
        ]
        assert len(lines) == 1 and others == lines, err
        assert any(n in lines[0] for n in names), f"error names none of {names}: {lines[0]}"
    assert _sha(inputs) == before, f"an input changed: {args}"
    assert wall < TIME_CEILING_S, f"{wall:.1f} s: {args}"
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    assert rss < MEMORY_CEILING_B, f"peak RSS {rss / 2**30:.2f} GiB after {args}"
    return code


# ------------------------------------------------------------------ G-code text

_NUM = st.one_of(
    st.integers(-200, 200).map(str),
    st.floats(-1e4, 1e4, allow_nan=False).map(lambda v: f"{v:.3f}"),
    st.sampled_from(["0", "-0", ".5", "1e9", "30000000", "-.", "", "1.2.3", "nan", "9" * 30]),
)
_WORD = st.tuples(st.sampled_from(list("GMXYZIJKRFSPNTHDABCQ")), _NUM).map("".join)
_BLOCK = st.one_of(
    st.lists(_WORD, min_size=1, max_size=5).map(" ".join),
    st.sampled_from(
        [
            "G0 X0 Y0 Z5",
            "G1 Z-1 F400",
            "G1 X30 F400",
            "G2 X10 Y10 I5 J5",
            "G3 X0 Y0 R5",
            "M5",
            "S0",
            "M3",
            "G91",
            "G20",
            "G28",
            "(comment",
            "%",
            "/G1 X5",
            "G4 P1",
            "T2 M6",
        ]
    ),
    st.text(max_size=12),
)


@settings(FUZZ, max_examples=40)
@given(blocks=st.lists(_BLOCK, max_size=8), target=st.sampled_from(["plan", "plan", "simulate"]))
def test_fuzz_gcode(blocks: list[str], target: str, capsys: pytest.CaptureFixture[str]) -> None:
    with _tmpdir() as d:
        prog = d / "fuzz.nc"
        prog.write_text("G21 G90 G94 G17\nS6000 M3\n" + "\n".join(blocks) + "\nM30\n")
        if target == "plan":
            args = [
                "plan",
                str(prog),
                "--stock",
                str(DEMO / "stock.toml"),
                "--tool",
                str(DEMO / "tool.toml"),
                "--material",
                str(DEMO / "material.toml"),
                "--resolution-mm",
                "1",
                "-o",
                str(d / "p.parquet"),
            ]
        else:
            args = [
                "simulate",
                "--program",
                str(prog),
                "--duration-s",
                "0.02",
                "-o",
                str(d / "s.h5"),
            ]
        _check(args, [prog, DEMO / "stock.toml", DEMO / "tool.toml"], ["fuzz.nc", "--"], capsys)


# ------------------------------------------------------------------ TOML files


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{json.dumps(k)} = {_toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def _dump_toml(data: dict[str, Any]) -> str:
    """TOML text of ``data`` (tables written inline)."""
    return "".join(f"{json.dumps(k)} = {_toml_value(v)}\n" for k, v in data.items())


def _leaves(data: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    if isinstance(data, dict):
        return [p for k, v in data.items() for p in _leaves(v, (*path, k))] or [path]
    if isinstance(data, list) and data and isinstance(data[0], dict):
        return [p for i, v in enumerate(data) for p in _leaves(v, (*path, i))]
    return [path]


_DELETE = object()
_VALUE = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -1.0, 1e-300, 1e300, 0, -5, 2**40]),
    st.integers(-(10**6), 10**6),
    st.text(max_size=6),
    st.booleans(),
    st.lists(st.floats(-1e3, 1e3), max_size=3),
    st.just(_DELETE),
    st.builds(lambda: {"unknown_key": 1}),  # a fresh dict each draw (it may be mutated)
)


def _mutated(base: dict[str, Any], data: st.DataObject) -> dict[str, Any]:
    doc = json.loads(json.dumps(base))  # deep copy
    for _ in range(data.draw(st.integers(1, 2))):
        path = data.draw(st.sampled_from(_leaves(doc)))
        if not path:
            break
        parent = doc
        for p in path[:-1]:
            parent = parent[p]
        value = data.draw(_VALUE)
        if value is _DELETE:
            del parent[path[-1]]
        else:
            parent[path[-1]] = value
    if data.draw(st.booleans()):
        doc[data.draw(st.sampled_from(["extra", "name", "source"]))] = data.draw(
            _VALUE.filter(lambda v: v is not _DELETE)
        )
    return doc


_KINDS = {
    "tool": DEMO / "tool.toml",
    "material": DEMO / "material.toml",
    "stock": DEMO / "stock.toml",
}


@settings(FUZZ, max_examples=80)
@given(kind=st.sampled_from(sorted(_KINDS)), raw=st.booleans(), data=st.data())
def test_fuzz_tool_material_stock_toml(
    kind: str, raw: bool, data: st.DataObject, capsys: pytest.CaptureFixture[str]
) -> None:
    with _tmpdir() as d:
        prog = d / "p.nc"
        prog.write_text(SMALL_PROGRAM)
        bad = d / f"fuzz-{kind}.toml"
        if raw:
            bad.write_bytes(data.draw(st.binary(max_size=40)))
        else:
            base = tomllib.loads(_KINDS[kind].read_text())
            bad.write_text(_dump_toml(_mutated(base, data)))
        files = {k: str(v) for k, v in _KINDS.items()}
        files[kind] = str(bad)
        args = [
            "plan",
            str(prog),
            "--stock",
            files["stock"],
            "--tool",
            files["tool"],
            "--material",
            files["material"],
            "--resolution-mm",
            "1",
            "-o",
            str(d / "p.parquet"),
        ]
        _check(args, [prog, bad], [bad.name], capsys)


@settings(FUZZ, max_examples=25)
@given(data=st.data())
def test_fuzz_machine_toml(data: st.DataObject, capsys: pytest.CaptureFixture[str]) -> None:
    base = tomllib.loads((DATA / "machines" / "quaser-ux600.toml").read_text())
    with _tmpdir() as d:
        prog = d / "p.nc"
        prog.write_text(SMALL_PROGRAM)
        bad = d / "fuzz-machine.toml"
        bad.write_text(_dump_toml(_mutated(base, data)))
        args = [
            "simulate",
            "--machine",
            str(bad),
            "--program",
            str(prog),
            "--duration-s",
            "0.02",
            "-o",
            str(d / "s.h5"),
        ]
        _check(args, [prog, bad], [bad.name], capsys)


# ------------------------------------------------------------------ recordings


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short simulated cut to damage (0.5 s; the feed starts at 0.30 s, after the spindle's
    run-up, and the tool is in the stock from 0.35 s)."""
    d = tmp_path_factory.mktemp("fuzz-rec")
    prog = d / "p.nc"
    prog.write_text(SMALL_PROGRAM)
    out = d / "run.h5"
    from millsense.cli.main import main

    try:
        main(["simulate", "--program", str(prog), "--duration-s", "0.5", "-o", str(out)])
    except SystemExit as exc:
        assert not exc.code, exc.code
    return out


def _datasets(f: h5py.File) -> list[str]:
    out: list[str] = []
    f["channels"].visititems(lambda n, o: out.append(n) if isinstance(o, h5py.Dataset) else None)
    return sorted(out)


_DAMAGE = ["truncate", "delete", "nan", "dtype", "shorten", "attr"]


def _damage(path: Path, how: str, data: st.DataObject) -> None:
    if how == "truncate":
        raw = path.read_bytes()
        path.write_bytes(raw[: data.draw(st.integers(0, len(raw) - 1))])
        return
    with h5py.File(path, "r+") as f:
        names = _datasets(f)
        name = "channels/" + data.draw(st.sampled_from(names))
        ds = f[name]
        attrs = dict(ds.attrs)
        values = ds[()]
        if how == "delete":
            del f[name]
        elif how == "nan":
            v = values.astype(np.float64)
            lo = data.draw(st.integers(0, len(v) - 1))
            v[lo : lo + data.draw(st.integers(1, 500))] = data.draw(
                st.sampled_from([np.nan, np.inf, -np.inf, 1e308])
            )
            ds[...] = v.astype(values.dtype) if values.dtype.kind == "f" else 0
            if values.dtype.kind == "f":
                ds[...] = v
        else:
            del f[name]
            if how == "dtype":
                new = data.draw(
                    st.sampled_from(
                        [values.astype(np.int8), values.astype("S8"), values.astype(np.complex64)]
                    )
                )
            elif how == "shorten":
                new = values[: data.draw(st.integers(0, len(values) - 1))]
            else:  # attr: a unit or the sample rate damaged
                new = values
            ds2 = f.create_dataset(name, data=new)
            for k, v in attrs.items():
                ds2.attrs[k] = v
            if how == "attr":
                key = data.draw(st.sampled_from(["unit", "sample_rate_hz", "metadata_json"]))
                bad = data.draw(st.sampled_from(["", "furlongs", "-1", "{", "nan"]))
                if key == "unit":
                    ds2.attrs["unit"] = bad
                else:
                    f.attrs[key] = bad


@settings(FUZZ, max_examples=25)
@given(how=st.sampled_from(_DAMAGE), command=st.sampled_from(["info", "estimate"]), data=st.data())
def test_fuzz_recordings(
    recording: Path,
    how: str,
    command: str,
    data: st.DataObject,
    capsys: pytest.CaptureFixture[str],
) -> None:
    with _tmpdir() as d:
        rec = d / "fuzz-run.h5"
        shutil.copyfile(recording, rec)
        _damage(rec, how, data)
        if command == "info":
            args = ["info", str(rec)]
        else:
            args = [
                "estimate",
                str(rec),
                "--machine",
                SIM_QUASER,
                "--method",
                "raw",
                "--axes",
                "x,y",
                "-o",
                str(d / "e.h5"),
            ]
        _check(args, [rec], [rec.name, "--"], capsys)


# ------------------------------------------------------------------ CLI arguments

_ARG = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(10**12), 10**12).map(str),
    st.sampled_from(
        [
            "0",
            "-0",
            "1e-300",
            "1e300",
            "nan",
            "inf",
            "",
            "x",
            "1,2",
            "1,2,3",
            "slot",
            "ae_mm=5",
            "ae_mm=-1,up",
            "ae_mm=x",
            "a:b",
            "1:0",
            "auto",
        ]
    ),
    st.text(max_size=8),
)

_OPTIONS: dict[str, list[str]] = {
    "plan": ["--step-mm", "--resolution-mm", "--home-mm"],
    "schedule": [
        "--limit-force-n",
        "--min-feed-mm-min",
        "--max-feed-mm-min",
        "--accel-mm-s2",
        "--step-mm",
    ],
    "simulate": [
        "--depth-mm",
        "--engagement",
        "--duration-s",
        "--chunk",
        "--air-mm",
        "--break-at-s",
        "--break-flute",
        "--cnc",
        "--seed",
        "--tool",
        "--machine",
    ],
    "estimate": ["--chunk", "--axes", "--method", "--flutes", "--air-s", "--idle", "--band-hz"],
}


def _base_args(command: str, d: Path, prog: Path, rec: Path) -> tuple[list[str], list[Path]]:
    stock = [
        "--stock",
        str(DEMO / "stock.toml"),
        "--tool",
        str(DEMO / "tool.toml"),
        "--material",
        str(DEMO / "material.toml"),
        "--resolution-mm",
        "1",
    ]
    if command == "plan":
        return ["plan", str(prog), *stock, "-o", str(d / "p.parquet")], [prog]
    if command == "schedule":
        return ["schedule", str(prog), *stock, "-o", str(d / "o.nc")], [prog]
    if command == "simulate":
        return [
            "simulate",
            "--program",
            str(prog),
            "--duration-s",
            "0.02",
            "-o",
            str(d / "s.h5"),
        ], [prog]
    return [
        "estimate",
        str(rec),
        "--machine",
        SIM_QUASER,
        "--method",
        "raw",
        "-o",
        str(d / "e.h5"),
    ], [rec]


@settings(FUZZ, max_examples=60)
@given(command=st.sampled_from(sorted(_OPTIONS)), data=st.data())
def test_fuzz_cli_arguments(
    recording: Path, command: str, data: st.DataObject, capsys: pytest.CaptureFixture[str]
) -> None:
    opts = data.draw(
        st.lists(st.tuples(st.sampled_from(_OPTIONS[command]), _ARG), min_size=1, max_size=3)
    )
    with _tmpdir() as d:
        prog = d / "p.nc"
        prog.write_text(SMALL_PROGRAM)
        args, inputs = _base_args(command, d, prog, recording)
        flat = [x for o, v in opts for x in (o, v)]
        if command == "schedule" and not any(o.startswith("--limit") for o, _ in opts):
            flat += ["--limit-force-n", "300"]
        names = [o for o, _ in opts] + ["--limit", "-o", "--output", "p.nc", "recording"]
        names += [Path(v).name for _, v in opts if v]  # a value read as a file names itself
        _check([*args, *flat], inputs, names, capsys)
