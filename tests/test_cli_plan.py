"""``millsense plan`` / ``schedule``: success on the demo part, one-line errors (exit 2)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from millsense.cli.main import main

DEMO = Path(__file__).resolve().parents[1] / "examples" / "demo_part"


def _run(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    try:
        main(args)
        code = 0
    except SystemExit as exc:
        code = int(exc.code or 0)
    out = capsys.readouterr()
    return code, out.out, out.err


def _common() -> list[str]:
    return [
        "--stock", str(DEMO / "stock.toml"),
        "--tool", str(DEMO / "tool.toml"),
        "--material", str(DEMO / "material.toml"),
    ]  # fmt: skip


def test_plan_bad_program_names_file_and_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    prog = tmp_path / "bad.nc"
    prog.write_text("G21 G90\nS1000 M3\nG1 X10 Y0 Z0 F400\nG41 X20\nM30\n")
    out = tmp_path / "p.parquet"
    code, _, err = _run(["plan", str(prog), *_common(), "-o", str(out)], capsys)
    assert code == 2
    assert err.strip().count("\n") == 0 and "bad.nc:4" in err
    assert not out.exists()  # nothing written after a failure


def test_plan_bad_config_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    stock = tmp_path / "stock.toml"
    stock.write_text('kind = "box"\nmin_mm = [0, 0, 0]\nmax_mm = [10, 10, -1]\n')
    args = [
        "plan",
        str(DEMO / "program.nc"),
        "--stock",
        str(stock),
        "--tool",
        str(DEMO / "tool.toml"),
        "--material",
        "al7050",
        "-o",
        str(tmp_path / "p.parquet"),
    ]
    code, _, err = _run(args, capsys)
    assert code == 2 and "stock.toml" in err and err.strip().count("\n") == 0


def test_plan_demo_part_writes_parquet_and_plot(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from millsense.plan.virtual_plan import VirtualPlan

    out = tmp_path / "p.parquet"
    png = tmp_path / "p.png"
    code, _, _ = _run(
        ["plan", str(DEMO / "program.nc"), *_common(), "-o", str(out), "--plot", str(png)], capsys
    )
    assert code == 0 and png.stat().st_size > 10_000
    plan = VirtualPlan.read(out)
    assert len(plan) >= 5000  # issue 4: demo part ≥ 5 000 steps
    # demo at 400 mm/min, 1000 rev/min, 2 flutes → 0.2 mm/tooth wherever F400 cuts
    cut = plan["in_cut"] & (plan["feed_mm_min"] == 400.0)
    assert plan["chip_load_mm"][cut].min() == pytest.approx(0.2)


def test_schedule_writes_program(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "opt.nc"
    code, stdout, _ = _run(
        ["schedule", str(DEMO / "program.nc"), *_common(), "--limit-force-n", "325",
         "-o", str(out)], capsys)  # fmt: skip
    assert code == 0 and "force limit" in stdout
    assert out.read_text().count("\n") > 80
    code, _, err = _run(["schedule", str(DEMO / "program.nc"), *_common(), "-o", str(out)], capsys)
    assert code == 2 and "exactly one" in err


def test_schedule_keeps_a_cp1252_comment(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A program with a cp1252 comment (read as latin-1, as the interpreter reads it) came out
    with U+FFFD in place of 'Ä' and 'Ø' (read as UTF-8 with errors replaced): the scheduled
    program keeps the input's bytes outside the rewritten F words, and the walkthrough slot's
    2 mm cut at 1200 mm/min above a 200 N limit is slowed (block N50 ends below F1200)."""
    src = Path(__file__).resolve().parents[1] / "examples" / "walkthrough" / "slot.nc"
    prog = tmp_path / "slot.nc"
    prog.write_bytes(src.read_bytes().replace(b"(T1 D=20.", "(FRÄSER Ø20.".encode("cp1252")))
    out = tmp_path / "opt.nc"
    code, _, err = _run(
        ["schedule", str(prog), *_common(), "--resolution-mm", "0.5", "--limit-force-n", "200",
         "-o", str(out)], capsys)  # fmt: skip
    assert code == 0, err
    lines = out.read_bytes().split(b"\n")
    assert lines[3].startswith("(FRÄSER Ø20.".encode("cp1252"))
    n50 = next(ln for ln in lines if ln.startswith(b"N50"))
    feeds = [float(w[1:]) for w in n50.decode().split() if w.startswith("F")]
    assert len(feeds) == 1 and feeds[0] < 1200.0


@pytest.mark.parametrize("home", ["0,0,nan", "inf,0,100"])
def test_plan_home_must_be_finite(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], home: str
) -> None:
    """``--home-mm 0,0,nan`` was taken and surfaced as "the path length is not finite
    (line 7, nan m)", blaming the program's G28 line: the option is named, exit 2."""
    prog = tmp_path / "g28.nc"
    prog.write_text(
        "G21 G90\nS6000 M3\nG0 X-15 Y40 Z5\nG1 Z-2 F600\nG1 X40 F1200\nG28 G91 Z0\nM30\n"
    )
    out = tmp_path / "p.parquet"
    code, _, err = _run(["plan", str(prog), *_common(), "--home-mm", home, "-o", str(out)], capsys)
    assert code == 2 and f"--home-mm '{home}': X,Y,Z must be finite" in err
    assert len(err.strip().splitlines()) == 1 and not out.exists()


@pytest.mark.parametrize("resolution", ["100", "14"])
def test_plan_zmap_cell_must_resolve_a_slot(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], resolution: str
) -> None:
    """``--resolution-mm 100`` (100 µm meant) made the demo part's z-map cells larger than the
    Ø20 mm tool: the plan said "0 in cut, peak resultant 0.0 N" with exit 0. The CWE resolves
    no radial depth below about 1.5 cells (plan.cwe's notes), so a cell of D/1.5 = 13.3 mm or
    more resolves not even a slot: one line naming the limit, exit 2, nothing written."""
    out = tmp_path / "p.parquet"
    code, _, err = _run(
        ["plan", str(DEMO / "program.nc"), *_common(), "--resolution-mm", resolution,
         "-o", str(out)], capsys)  # fmt: skip
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert f"--resolution-mm {resolution}: a cell of D/1.5 = 13.33 mm or more" in err
    assert not out.exists()


@pytest.mark.parametrize(
    ("opts", "message"),
    [
        (["--limit-force-n", "inf"], "--limit-force-n inf: must be finite"),
        (["--limit-force-n", "nan"], "--limit-force-n nan: must be finite"),
        (["--limit-torque-nm", "0"], "--limit-torque-nm 0.0: must be > 0"),
        (["--limit-force-n", "200", "--max-feed-mm-min", "inf"], "--max-feed-mm-min inf: must"),
        (["--limit-force-n", "200", "--accel-mm-s2", "inf"], "--accel-mm-s2 inf: must be finite"),
    ],
)
def test_schedule_limits_named_as_given(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], opts: list[str], message: str
) -> None:
    """``--limit-force-n inf`` was blamed on "--min-feed-mm-min None" (the scheduler's own
    error passed through as the minimum feed's), ``--limit-torque-nm 0`` was reported as
    "--limit-torque", and an infinite acceleration was taken: one line naming the option as
    it is spelt, exit 2, nothing written."""
    out = tmp_path / "opt.nc"
    code, _, err = _run(["schedule", str(DEMO / "program.nc"), *_common(), *opts, "-o",
                         str(out)], capsys)  # fmt: skip
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_plan_warns_of_a_rapid_through_material(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A G0 across the demo block at Z-2 (line 5; a slot's depth where a G1 was meant) is a
    collision on a machine: `plan` warns once, naming the program's line, and writes the plan
    with the warning in its metadata (it was a note among the plan's notes before)."""
    prog = tmp_path / "rapid.nc"
    prog.write_text("G21 G90 G17\nS1000 M3\nG0 X-15 Y40 Z5\nG0 Z-2\nG0 X30\nG1 X60 F400\nG0 Z5\n"
                    "M30\n")
    out = tmp_path / "p.parquet"
    code, stdout, err = _run(["plan", str(prog), *_common(), "-o", str(out)], capsys)
    assert code == 0, err
    warnings = [w for w in err.splitlines() if "rapid (G0) moves through material" in w]
    assert len(warnings) == 1 and "rapid.nc:5" in warnings[0] and "collision" in warnings[0]
    assert "rapid (G0)" not in stdout
    from millsense.plan.virtual_plan import VirtualPlan

    assert any("rapid (G0)" in w for w in VirtualPlan.read(out).metadata["warnings"])


def test_the_tool_starts_above_a_stock_that_stands_above_z0(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Decision 1709: a block whose top is at Z+10 mm (the work origin inside it) and a program
    whose first move rapids to a safe Z above it. Started at X0 Y0 Z0 the plan would begin
    inside the block and warn of a collision on line 3 that the program never makes; it starts
    at X0 Y0 Z10, on the top, out of the material, and the slot on line 5 is 2 mm deep."""
    stock = tmp_path / "stock.toml"
    stock.write_text('kind = "box"\nmin_mm = [-50, -50, -20]\nmax_mm = [50, 50, 10]\n')
    prog = tmp_path / "above.nc"
    prog.write_text("G21 G90 G17\nS3000 M3\nG0 X-70 Y0 Z15\nG0 Z8\nG1 X70 F600\nG0 Z20\nM30\n")
    out = tmp_path / "p.parquet"
    args = ["plan", str(prog), "--stock", str(stock), "--tool", "aslan-d20-2flute",
            "--material", "al7050", "--resolution-mm", "0.5", "-o", str(out)]  # fmt: skip
    code, _, err = _run(args, capsys)
    assert code == 0, err
    assert "moves through material" not in err
    from millsense.plan.virtual_plan import VirtualPlan

    plan = VirtualPlan.read(out)
    assert (plan["x_mm"][0], plan["y_mm"][0], plan["z_mm"][0]) == (0.0, 0.0, 10.0)
    rapid_cut = np.asarray(plan["in_cut"], bool) & np.asarray(plan["rapid"], bool)
    assert not rapid_cut.any()
    line5 = np.asarray(plan["source_line"]) == 5
    depth = np.asarray(plan["axial_depth_mm"])[line5 & np.asarray(plan["in_cut"], bool)]
    assert np.median(depth) == pytest.approx(2.0, abs=0.5)  # one 0.5 mm cell


def test_the_demo_part_still_starts_at_the_work_origin(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Decision 1709 moves the start only for a stock above Z0: the demo block's top is Z0, so
    its plan starts at X0 Y0 Z0 as before."""
    out = tmp_path / "p.parquet"
    code, _, err = _run(["plan", str(DEMO / "program.nc"), *_common(), "--resolution-mm", "1",
                         "-o", str(out)], capsys)  # fmt: skip
    assert code == 0, err
    from millsense.plan.virtual_plan import VirtualPlan

    plan = VirtualPlan.read(out)
    assert (plan["x_mm"][0], plan["y_mm"][0], plan["z_mm"][0]) == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("below_mm", [0.0, 0.3, 2.0])
def test_plan_through_the_stock_bottom_cuts_with_the_flutes_inside_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], below_mm: float
) -> None:
    """A slot through a 10 mm plate with the tip 0, 0.3 and 2 mm below its bottom: the
    flutes below the bottom cut nothing, so the axial depth is the plate (10 mm; it was the
    tip's 10.3 and 12 mm, and the layers under the bottom were dropped whole, leaving 10.3
    and 9.6 mm of cutting edge) and the mean torque the hand computation of a slot:
    T = N R a / (2π) · 2 K_tc c (shear part; Ø20 2-flute, a = 10 mm, c = 0.1 mm/tooth,
    K_tc = 758 N/mm²) = 4.8256 N·m. Tolerance 1e-6: the z-map's float32 heights and exact
    slot intervals [0, π]."""
    from millsense.plan.virtual_plan import VirtualPlan

    stock = tmp_path / "plate.toml"
    stock.write_text('kind = "box"\nmin_mm = [0, 0, -10]\nmax_mm = [60, 40, 0]\n')
    prog = tmp_path / "through.nc"
    z = -10.0 - below_mm
    prog.write_text(
        f"G21 G90 G17\nS6000 M3\nG0 X-15 Y20 Z5\nG1 Z{z:.1f} F600\nG1 X75 F1200\nG0 Z5\nM30\n"
    )
    out = tmp_path / "p.parquet"
    args = ["plan", str(prog), "--stock", str(stock), "--tool", "aslan-d20-2flute"]
    args += ["--material", "al7050", "--resolution-mm", "0.5", "-o", str(out)]
    code, _, err = _run(args, capsys)
    assert code == 0, err
    plan = VirtualPlan.read(out)
    mid = (plan["x_mm"] > 20) & (plan["x_mm"] < 40) & plan["in_cut"]
    assert mid.sum() >= 40
    assert plan["axial_depth_mm"][mid] == pytest.approx(10.0, rel=1e-6)
    assert plan["engaged_area_mm2"][mid] == pytest.approx(200.0, rel=1e-6)  # a D
    hand = 2 * 10.0 * 10.0 / (2 * np.pi) * 2 * 758.0 * 0.1 * 1e-3  # N·mm → N·m
    assert plan["ktc_n_mm2"][mid] == pytest.approx(758.0)
    assert plan["torque_avg_shear_nm"][mid] == pytest.approx(hand, rel=1e-6)


_TWO_TOOLS = """G21 G90 G17
T1 M6
S6000 M3
G0 X-15 Y20 Z5
G1 Z-2 F600
G1 X75 F1200
G0 Z5
T2 M6
S8000 M3
G0 X-15 Y20
G1 Z-2 F600
G1 X75 F800
G1 Z-4 F300
G1 X-15 F800
G0 Z5
M30
"""


def _two_tools(tmp_path: Path) -> tuple[Path, Path, Path]:
    stock = tmp_path / "plate.toml"
    stock.write_text('kind = "box"\nmin_mm = [0, 0, -10]\nmax_mm = [60, 40, 0]\n')
    prog = tmp_path / "two.nc"
    prog.write_text(_TWO_TOOLS)
    t2 = tmp_path / "d10.toml"
    t2.write_text(
        'name = "D10"\nshape = "flat"\ndiameter_mm = 10.0\nflutes = 3\nhelix_deg = 30.0\n'
    )
    return stock, prog, t2


def test_plan_each_tool_of_a_program_with_its_tool_on_one_stock(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Decision 1683: T1 (Ø20) slots 2 mm deep, T2 (Ø10, 3 flutes) runs the same line at the
    same depth, then 2 mm deeper. One plan per tool; T2's plan starts from the stock T1 left,
    so its first pass cuts nothing (was: refused), its second one is a Ø10 slot 2 mm deep:
    engaged area a D = 2 x 10 = 20 mm² (T1's: 2 x 20 = 40 mm²), exact slot intervals (1e-6)."""
    from millsense.plan.virtual_plan import VirtualPlan

    stock, prog, t2 = _two_tools(tmp_path)
    out = tmp_path / "p.parquet"
    args = ["plan", str(prog), "--stock", str(stock), "--tool", "T1=aslan-d20-2flute"]
    args += ["--tool", f"T2={t2}", "--material", "al7050", "--resolution-mm", "0.25"]
    code, std, err = _run([*args, "-o", str(out), "--plot", str(tmp_path / "p.png")], capsys)
    assert code == 0, err
    assert not out.exists()
    p1, p2 = (
        VirtualPlan.read(tmp_path / "p_T1.parquet"),
        VirtualPlan.read(tmp_path / "p_T2.parquet"),
    )
    assert (tmp_path / "p_T1.png").stat().st_size > 10_000
    assert (tmp_path / "p_T2.png").stat().st_size > 10_000
    assert p1.metadata["tool"]["diameter_mm"] == 20.0 and p2.metadata["tool"]["diameter_mm"] == 10.0
    assert p1.metadata["tool_number"] == 1 and p2.metadata["tool_number"] == 2
    assert p2.metadata["segment_first_line"] == 8  # the line of T2 M6
    mid1 = (p1["x_mm"] > 20) & (p1["x_mm"] < 40) & p1["in_cut"]
    assert mid1.sum() >= 40
    assert p1["engaged_area_mm2"][mid1] == pytest.approx(40.0, rel=1e-6)
    first = p2["source_line"] == 12  # G1 X75 at Z-2: inside T1's slot
    assert first.sum() > 100 and not p2["in_cut"][first].any()
    second = (p2["source_line"] == 14) & (p2["x_mm"] > 20) & (p2["x_mm"] < 40) & p2["in_cut"]
    assert second.sum() >= 40
    assert p2["axial_depth_mm"][second] == pytest.approx(2.0, rel=1e-6)
    assert p2["engaged_area_mm2"][second] == pytest.approx(20.0, rel=1e-6)
    assert "p_T1.parquet" in std and "p_T2.parquet" in std


def test_a_program_note_is_printed_once_for_all_tools(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Every tool's plan keeps the program's notes; `plan` printed each once per tool (an M1
    of a two-tool program: its note twice)."""
    stock, prog, t2 = _two_tools(tmp_path)
    prog.write_text(_TWO_TOOLS.replace("G0 Z5\nT2 M6", "G0 Z5\nM1\nT2 M6"))
    args = ["plan", str(prog), "--stock", str(stock), "--tool", "T1=aslan-d20-2flute"]
    args += ["--tool", f"T2={t2}", "--material", "al7050", "--resolution-mm", "0.25"]
    code, _, err = _run([*args, "-o", str(tmp_path / "p.parquet")], capsys)
    assert code == 0, err
    assert err.count("two.nc:8: optional stop M1 ignored") == 1, err


def test_plot_of_one_tools_plan_names_the_tool(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Each tool's plot was titled with the program alone ("two.nc" on both): the tool's
    number and name follow it."""
    from matplotlib.figure import Figure

    from millsense.plan.virtual_plan import VirtualPlan
    from millsense.report.plan_plots import plot_plan

    stock, prog, t2 = _two_tools(tmp_path)
    out = tmp_path / "p.parquet"
    args = ["plan", str(prog), "--stock", str(stock), "--tool", "T1=aslan-d20-2flute"]
    args += ["--tool", f"T2={t2}", "--material", "al7050", "--resolution-mm", "0.5"]
    try:
        main([*args, "-o", str(out)])
    except SystemExit as exc:
        assert not exc.code
    titles: list[str] = []
    real = Figure.suptitle
    monkeypatch.setattr(Figure, "suptitle", lambda f, t, **kw: titles.append(t) or real(f, t, **kw))
    plot_plan(VirtualPlan.read(tmp_path / "p_T2.parquet"), tmp_path / "t2.png")
    assert titles == [f"{prog}: T2 (D10)"]


@pytest.mark.parametrize(
    ("tools", "expect"),
    [
        (["aslan-d20-2flute"], "two.nc:8: tool change to T2 (the program uses T1, T2)"),
        (["T1=aslan-d20-2flute"], "two.nc:8: tool change to T2: no --tool T2=TOOL given"),
        (["T1=aslan-d20-2flute", "T2=x", "T3=y"], "the program uses T1, T2, not T3"),
        (["T1=aslan-d20-2flute", "aslan-d20-2flute"], "not both"),
    ],
)
def test_plan_tools_of_a_program_refused_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], tools: list[str], expect: str
) -> None:
    """One tool for two, a tool missing, one the program does not use, the forms mixed: one
    line (exit 2) naming the program's line where it applies, nothing written."""
    stock, prog, _ = _two_tools(tmp_path)
    out = tmp_path / "p.parquet"
    args = ["plan", str(prog), "--stock", str(stock), "--material", "al7050"]
    for t in tools:
        args += ["--tool", t]
    code, _, err = _run([*args, "-o", str(out)], capsys)
    assert code == 2 and err.strip().count("\n") == 0, err
    assert expect in err
    assert not list(tmp_path.glob("p*.parquet"))


def test_run_of_a_program_with_two_tools_names_the_line_and_the_remedy(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``run --program`` closes the loop on one tool: refused at the second tool's line with
    the per-tool plan as remedy, before anything is simulated or written."""
    stock, prog, _ = _two_tools(tmp_path)
    out = tmp_path / "r.h5"
    args = ["run", "--program", str(prog), "--stock", str(stock), "--tool", "aslan-d20-2flute"]
    code, _, err = _run([*args, "--material", "al7050", "-o", str(out)], capsys)
    assert code == 2 and err.strip().count("\n") == 0, err
    assert "two.nc:8: tool change to T2" in err and "--tool T1=TOOL --tool T2=TOOL" in err
    assert not out.exists()
    # the per-tool form gets the same remedy (decision 1683): before, `--tool T1=TOOL` was
    # asked for `--tool T2=TOOL`, which the one-tool command cannot take (a repeated --tool
    # keeps its last value, and T1 was then missing)
    args[-1] = "T1=aslan-d20-2flute"
    code, _, err = _run([*args, "--material", "al7050", "-o", str(out)], capsys)
    assert code == 2 and err.strip().count("\n") == 0, err
    assert "two.nc:8: tool change to T2" in err and "this command runs one tool" in err
    assert "--tool T1=TOOL --tool T2=TOOL" in err and "no --tool T2" not in err
    assert not out.exists()
