"""Fixed arc-length sampling of toolpaths: exact lengths, equal steps, time, tangents."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from millsense.core.units import MM, MM_PER_MIN, RPM
from millsense.plan.gcode import interpret
from millsense.plan.path import DEFAULT_STEP, sample_path

# (u, v, w) axis letters of G17, G18, G19 and the centre-offset letters of u and v.
_PLANES = {17: ("XYZ", "IJ"), 18: ("ZXY", "KI"), 19: ("YZX", "JK")}

_line = st.tuples(
    st.just("line"),
    st.booleans(),  # rapid?
    st.floats(-20, 20),
    st.floats(-20, 20),
    st.floats(-5, 5),
)
_arc = st.tuples(
    st.just("arc"),
    st.sampled_from([17, 18, 19]),
    st.sampled_from([2, 3]),
    st.floats(0.5, 20),  # radius, mm
    st.one_of(st.floats(0.05, 6.2), st.just(2 * math.pi)),  # sweep, rad
    st.floats(-math.pi, math.pi),  # start angle about the centre
    st.floats(-5, 5),  # travel along the arc axis, mm
)


def _f(v: float) -> str:
    """A G-code number (no exponent), rounded to 1e-12 mm: far below the test tolerances."""
    return f"{v:.12f}"


def _program(moves: list[tuple]) -> tuple[str, float]:
    """G-code for the drawn moves and their exact total length (mm), computed independently."""
    pos = {"X": 0.0, "Y": 0.0, "Z": 0.0}
    out = ["G21 G90 G94 F300", "G1 X0 Y0 Z0"]
    total = 0.0
    for mv in moves:
        if mv[0] == "line":
            _, rapid, dx, dy, dz = mv
            for ax, d in zip("XYZ", (dx, dy, dz), strict=True):
                pos[ax] += d
            out.append(f"{'G0' if rapid else 'G1'} X{_f(pos['X'])} Y{_f(pos['Y'])} Z{_f(pos['Z'])}")
            total += math.sqrt(dx * dx + dy * dy + dz * dz)
        else:
            _, plane, g, r, sweep, phi0, dw = mv
            (u, v, w), (lu, lv) = _PLANES[plane]
            cu = pos[u] - r * math.cos(phi0)
            cv = pos[v] - r * math.sin(phi0)
            phi1 = phi0 + (sweep if g == 3 else -sweep)
            end = dict(pos)
            if sweep < 2 * math.pi:
                end[u] = cu + r * math.cos(phi1)
                end[v] = cv + r * math.sin(phi1)
            end[w] = pos[w] + dw
            out.append(
                f"G{plane} G{g} X{_f(end['X'])} Y{_f(end['Y'])} Z{_f(end['Z'])} "
                f"{lu}{_f(cu - pos[u])} {lv}{_f(cv - pos[v])}"
            )
            pos = end
            total += math.hypot(r * sweep, dw)
    out.append("M30")
    return "\n".join(out), total


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.one_of(_line, _arc), min_size=1, max_size=8),
    st.sampled_from([0.1, 0.4, 1.3]),
)
def test_steps_equal_and_total_length_exact(moves: list[tuple], step_mm: float) -> None:
    text, total_mm = _program(moves)
    tp = interpret(text, source="prop.nc")
    step = step_mm * MM
    # Exact move lengths: interpreter's sum equals the independent closed-form sum.
    assert tp.lengths().sum() == pytest.approx(total_mm * MM, rel=1e-9, abs=1e-12)
    sp = sample_path(tp, step)
    if total_mm * MM < 1e-9:
        return
    ds = np.diff(sp.s)
    # Every step equals h (float rounding of k·h only), the last is in (0, h].
    assert np.all(np.abs(ds[:-1] - step) < 1e-9 * step)
    assert 0.0 < ds[-1] <= step * (1 + 1e-9)
    assert sp.s[-1] == pytest.approx(total_mm * MM, rel=1e-9, abs=1e-12)
    # A chord is never longer than the arc length it spans.
    chord = np.linalg.norm(np.diff(sp.xyz, axis=0), axis=1)
    assert np.all(chord <= ds * (1 + 1e-9) + 1e-12)
    # Time never decreases; tangents are unit vectors.
    assert np.all(np.diff(sp.t) >= 0.0)
    assert np.allclose(np.linalg.norm(sp.tangent, axis=1), 1.0, atol=1e-12)
    # The path ends at the last programmed point.
    assert sp.xyz[-1] == pytest.approx(tp.end[-1, :3], abs=1e-12)


def test_time_along_path_is_length_over_feed() -> None:
    tp = interpret(
        "G21 G90\nS1000 M3\nG0 X0 Y0 Z0\nG0 X40\nG1 X0 F400\nG4 P1.5\nG2 X0 Y0 I10 J0 F800\nM30",
        source="t.nc",
    )
    sp = sample_path(tp, rapid_rate=10_000 * MM_PER_MIN)
    # rapid 40 mm at 10 m/min + 40 mm at 400 mm/min + 1.5 s dwell + 20π mm at 800 mm/min.
    t_end = 40 / 10_000 * 60 + 40 / 400 * 60 + 1.5 + 20 * math.pi / 800 * 60
    assert sp.t[-1] == pytest.approx(t_end, rel=1e-12)
    # At s = 50 mm (10 mm into the feed line): 0.24 s + 10 mm / (400 mm/min).
    k = round(50 / 0.4)
    assert sp.s[k] == pytest.approx(50 * MM)
    assert sp.t[k] == pytest.approx(0.24 + 1.5, rel=1e-12)
    # Flags and per-step fields.
    assert sp.rapid[: k - 25].all() and not sp.rapid[k:].any()
    assert sp.feed[k] == pytest.approx(400 * MM_PER_MIN)
    assert sp.spindle_speed[k] == pytest.approx(1000 * RPM)
    assert sp.step == DEFAULT_STEP


def test_arc_samples_on_circle_with_tangent() -> None:
    tp = interpret("G21 G0 X10 Y0\nG3 X-10 Y0 I-10 J0 F100\nM30", source="t.nc")
    sp = sample_path(tp, step=0.25 * MM)
    on = sp.move == 1
    x, y = sp.x[on], sp.y[on]
    assert np.max(np.abs(np.hypot(x, y) - 10 * MM)) < 1e-15
    # CCW tangent of a circle about the origin is (-y, x)/r (closed form).
    expected = np.column_stack((-y, x, np.zeros_like(x))) / (10 * MM)
    assert np.max(np.abs(sp.tangent[on] - expected)) < 1e-12
    # Sample k on the arc is at angle k·h/r from the start (uniform arc length).
    s_local = sp.s[on] - sp.s[on][0]
    theta = np.unwrap(np.arctan2(y, x))
    assert np.max(np.abs(theta - theta[0] - s_local / (10 * MM))) < 1e-12


def test_line_tangent_and_boundary_sample() -> None:
    tp = interpret("G21 G1 X3 Y4 F100\nG1 X3 Y4 Z-2\nM30", source="t.nc")
    sp = sample_path(tp, step=1.0 * MM)
    assert sp.tangent[0] == pytest.approx([0.6, 0.8, 0.0])
    # s = 5 mm is the corner: it belongs to the second move and sits on the corner exactly.
    k = 5
    assert sp.move[k] == 1
    assert sp.xyz[k] == pytest.approx(np.array([3, 4, 0]) * MM, abs=1e-15)
    assert sp.tangent[k] == pytest.approx([0.0, 0.0, -1.0])
    assert len(sp) == 8  # s = 0..7 mm


def test_no_length_gives_empty_and_bad_step() -> None:
    tp = interpret("G21 G4 P1\nM30", source="t.nc")
    assert len(sample_path(tp)) == 0
    tp = interpret("G21 G1 X1 F10\nM30", source="t.nc")
    with pytest.raises(ValueError, match="positive"):
        sample_path(tp, step=0.0)
