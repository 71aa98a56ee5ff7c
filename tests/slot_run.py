"""The simulated slot of tests/test_cli_estimate.py and its x,y feed estimate, built once per
test session for every test that reads them: tests/conftest.py registers the fixtures
`slot_run` (:func:`slot_run_fixture`) and `slot_xy_feed` (:func:`slot_xy_feed_fixture`); imported
into a test module instead, a fixture would be built again for that module.

Scenario: quaser-ux600 (the simulator's own file), Ø20 mm 2-flute end mill, Al7050, slot 4 mm
deep along +X at 1200 mm/min and 3000 rev/min (tooth frequency 100 Hz), 1.3 s simulated with the
realism layer on, the first 6 mm of the feed move cut air. The simulation is seeded: the same
command gives the same file, so the tests that each simulated it read one copy.
"""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass
from pathlib import Path

import pytest

from millsense.cli.main import main
from millsense.simulator.machine_file import simulator_machine_path

#: The simulator's own quaser-ux600 file: these tests exercise the CLI on a fully specified machine
#: (the nameplate preset has no identified values; decision 0991).
SIM_QUASER = str(simulator_machine_path("quaser-ux600"))

SLOT = """G21 G90 G94
G0 X-15 Y0 Z0
S3000 M3
G1 X60 F1200
M5
M30
"""


def _cli(args: list[str]) -> str:
    """``millsense ARGS`` in-process; its standard output (exit status 0 asserted)."""
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out):
            main(args)
    except SystemExit as exc:
        assert not exc.code, f"millsense {' '.join(args)}: exit {exc.code}"
    return out.getvalue()


@pytest.fixture(scope="session", name="slot_run")
def slot_run_fixture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``millsense simulate`` of the slot (read-only for the tests)."""
    d = tmp_path_factory.mktemp("slot_run")
    prog = d / "slot.nc"
    prog.write_text(SLOT)
    out = d / "run.h5"
    _cli(["simulate", "--machine", SIM_QUASER, "--program", str(prog), "--depth-mm", "4",
          "--air-mm", "6", "--duration-s", "1.3", "--realism", "-o", str(out)])  # fmt: skip
    return out


@dataclass(frozen=True)
class XyFeed:
    """``millsense estimate RUN --machine COMMISSIONED --axes x,y --method feed --plot PNG``."""

    estimates: Path
    plot: Path
    stdout: str


@pytest.fixture(scope="session", name="slot_xy_feed")
def slot_xy_feed_fixture(
    tmp_path_factory: pytest.TempPathFactory, slot_run: Path, commissioned: Path
) -> XyFeed:
    """The x,y feed estimate of the slot with the machine file commissioned on the simulator's
    truth (tests/commissioned.py), as a user makes it: commission → identify → merge."""
    d = tmp_path_factory.mktemp("slot_xy_feed")
    feed, png = d / "feed.h5", d / "est.png"
    machine = str(commissioned / "machine.toml")
    stdout = _cli(["estimate", str(slot_run), "--machine", machine, "--axes", "x,y",
                   "--method", "feed", "-o", str(feed), "--plot", str(png)])  # fmt: skip
    return XyFeed(feed, png, stdout)
