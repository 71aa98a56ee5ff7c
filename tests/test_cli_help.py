"""Help that reads well (issue 21, decisions 0923 and 0924).

Walks every command's ``--help`` as the user sees it: no ``<bool>`` metavar on a flag; every
option whose value has a unit says the unit in its name and shows it in square brackets in its
help line (the rich renderer used to eat ``[mm]``); one name for one job (``-o/--output`` for
the file a command writes; no ``--out``).
"""

from __future__ import annotations

import typing
from pathlib import Path
from typing import Any

import pytest
import typer
import typer.core

from cli_run import run_cli
from millsense.cli.main import _register_commands, app

#: option-name suffix → the unit its help must show in brackets (longest suffix first)
UNIT_SUFFIXES = (
    ("-mm-min", "[mm/min]"),
    ("-mm-s2", "[mm/s²]"),
    ("-min", "[min]"),
    ("-mm", "[mm]"),
    ("-um", "[µm]"),
    ("-hz", "[Hz]"),
    ("-nm", "[N·m]"),
    ("-n", "[N]"),
    ("-w", "[W]"),
    ("-s", "[s]"),
    ("-rpm", "[rev/min]"),
    ("-deg", "[deg]"),
)

#: float options without a unit suffix, and why
UNITLESS_FLOATS = {
    "--kp": "a gain whose unit follows --error-unit (rev/s or rad/s), stated in its help",
    "--ki": "a gain whose unit follows --error-unit (rev/s or rad/s), stated in its help",
    "--tolerance": "a relative error bound (dimensionless fraction), stated in its help",
    "--reference": "a set point whose unit follows --regulate (W, N·m or N), stated in its help",
    "--speed": "serve-machine's real-time factor (dimensionless), stated in its help",
}


def _commands() -> dict[str, Any]:
    _register_commands()
    group: Any = typer.main.get_command(app)
    return dict(group.commands)


def _is_float(p: Any) -> bool:
    ann = p.type_descriptor.annotation
    return ann is float or float in typing.get_args(ann)


def _help_blocks(text: str) -> dict[str, str]:
    """Option help entries of a rendered help page: long name → its (unwrapped) text."""
    blocks: dict[str, str] = {}
    current: str | None = None
    for line in text.splitlines():
        stripped = line.strip()
        if line.startswith("  -") and stripped.startswith("-"):
            names = [w.rstrip(",") for w in stripped.split() if w.startswith("--")]
            current = names[0] if names else None
            if current is not None:
                blocks[current] = stripped
        elif current is not None and line.startswith("    ") and stripped:
            blocks[current] += " " + stripped
        else:
            current = None
    return blocks


def _unit(long_name: str) -> str | None:
    for suffix, unit in UNIT_SUFFIXES:
        if long_name.endswith(suffix):
            return unit
    return None


COMMANDS = sorted(_commands())


def test_every_command_is_walked() -> None:
    for name in ("demo", "estimate", "identify", "lobes", "plan", "plot", "recover", "simulate"):
        assert name in COMMANDS


@pytest.mark.parametrize("name", COMMANDS)
def test_help_has_plain_flags_and_visible_units(
    name: str, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("COLUMNS", "100")
    code, text, err = run_cli([name, "--help"], capsys)
    assert code == 0, err
    assert "<bool>" not in text
    blocks = _help_blocks(text)
    cmd = _commands()[name]
    for p in cmd.params:
        if not isinstance(p, typer.core.TyperOption) or p.hidden:
            continue
        longs = [o for o in p.opts if o.startswith("--")]
        assert longs, f"{name}: option {p.opts} has no long name"
        long_name = longs[0]
        assert long_name != "--out", f"{name}: --out; the output option is -o/--output"
        assert long_name in blocks, f"{name}: {long_name} not in its help page"
        if p.is_flag:
            # a flag shows no value metavar: '--realism  Switch on ...'
            assert blocks[long_name].split()[1] not in ("<bool>", "BOOLEAN"), blocks[long_name]
        unit = _unit(long_name)
        if unit is not None:
            assert unit in blocks[long_name], f"{name} {long_name}: no {unit} in its help"
        elif _is_float(p):
            assert long_name in UNITLESS_FLOATS, f"{name} {long_name}: a value without unit"
        if "-o" in p.opts:
            assert "--output" in p.opts, f"{name}: -o is not -o/--output"


def test_validate_markdown_dash_is_stdout_not_a_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """`--markdown -` once wrote a file named '-' (committed at the repository root)."""
    monkeypatch.chdir(tmp_path)
    case = "stability.sdm.hayes_spectral_radius"
    code, out, err = run_cli(["validate", "--case", case, "--markdown", "-"], capsys)
    assert code == 0, err
    assert out.startswith("# Validation") and f"`{case}`" in out
    assert list(tmp_path.iterdir()) == []


def test_register_only_the_command_run() -> None:
    # decision 2007: a fresh `millsense batch` imports cmd_batch alone; a command whose module
    # has another name (simulate-fleet lives in cmd_fleet) imports them all and is found
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from millsense.cli.main import _register_commands, _registered_names\n"
        "_register_commands(sys.argv[1])\n"
        "mods = sorted(m for m in sys.modules if m.startswith('millsense.cli.cmd_'))\n"
        "print(len(mods), sys.argv[1] in _registered_names(), ' '.join(mods))\n"
    )
    one = subprocess.run([sys.executable, "-c", code, "batch"], capture_output=True, text=True,
                         check=True).stdout.split()  # fmt: skip
    assert one == ["1", "True", "millsense.cli.cmd_batch"]
    every = subprocess.run([sys.executable, "-c", code, "simulate-fleet"], capture_output=True,
                           text=True, check=True).stdout.split()  # fmt: skip
    import millsense.cli

    n_modules = sum(1 for p in Path(millsense.cli.__file__).parent.glob("cmd_*.py"))
    assert every[:2] == [str(n_modules), "True"]


def test_fast_exit_runs_the_exit_handlers_and_nothing_after_main(tmp_path: Path) -> None:
    # decision 2007: a command that allows the fast exit ends the process inside main() after
    # the exit handlers; its file is written; a caller passing argv never exits
    import subprocess
    import sys

    target = tmp_path / "probe.txt"
    code = (
        "import atexit, sys\n"
        "from millsense.cli import main as m\n"
        "@m.app.command('probe')\n"
        "def probe(path: str) -> None:\n"
        "    open(path, 'w').write('written')\n"
        "    m.allow_fast_exit()\n"
        "atexit.register(lambda: print('exit handler ran', flush=True))\n"
        "sys.argv = ['millsense', 'probe', sys.argv[1]]\n"
        "m.main()\n"
        "print('after main', flush=True)\n"
    )
    done = subprocess.run([sys.executable, "-c", code, str(target)], capture_output=True,
                          text=True, timeout=120)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert done.stdout.split("\n")[0] == "exit handler ran"
    assert "after main" not in done.stdout
    assert target.read_text() == "written"
