"""The virtual plan: one row per path step with engagement and predicted process states.

Seed 000 (Aslan, §0, §6, C15, V9) feeds the online algorithms from a "virtual feedback file":
one row per 0.4 mm of tool path with position, feed, in-cut flag, Gain_CWE, K_tc, F_res and
NC line, plus (§6) the mean torque per tooth period and the CWE area and chip load for the
look-ahead. :class:`VirtualPlan` is that file, as Parquet (pyarrow; readable by duckdb,
polars, pandas), field units in the column names (``x_mm``, ``fres_peak_n``,
``torque_avg_nm``, ``feed_mm_min``), metadata (program, tool, material, stock, step,
software version) in the Parquet schema metadata under the key ``millsense``.

Format version 2 (:data:`PLAN_FORMAT_VERSION`) adds the full per-layer engagement in two list
columns (:data:`LAYER_COLUMNS`, decision "Plan file: per-layer engagement columns"):
``interval_counts`` (list<int16>, one count per layer, tip upwards) and ``intervals_rad``
(list<float32>, the valid (entry, exit) pairs of all layers in layer order, flattened), and the
tool, coefficients, discs and step in the metadata, so a plan drives the virtual machine on its
own (:mod:`millsense.plan.plan_engagement`). Version-1 plans (no such columns) still read;
their engagement is then the widest interval (``entry_deg``/``exit_deg``).

Build one with :func:`plan_program`; query it with :meth:`VirtualPlan.match` (the row of a
measured tool-centre position) and :meth:`VirtualPlan.look_ahead` (seed 000 §2.10 flags).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from operator import is_, itemgetter
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from millsense.core.errors import InputDataError, ProgramError
from millsense.core.units import MM, MM_PER_MIN, RPM, UM
from millsense.plan import _plan_kernels as _k
from millsense.plan.cwe import EngagementResult, compute_engagement
from millsense.plan.path import DEFAULT_STEP, SampledPath, Toolpath, sample_path
from millsense.plan.predict import STAT_NAMES, ForceBasis, predict_states
from millsense.plan.stock import ZMapStock
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.geometry import EndMill

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

#: Synchronisation tolerance per axis [m] (seed 000 C15, Table of §3: ±10 µm).
MATCH_TOLERANCE_M = 10 * UM
#: Look-ahead horizon [s] and rise threshold (seed 000 §2.10).
LOOK_AHEAD_S = 0.5
RISE_FRACTION = 0.15
#: Schema metadata key holding the JSON metadata.
META_KEY = b"millsense"
#: Plan file format version written by this module; versions 1..this are read.
PLAN_FORMAT_VERSION = 2
#: Optional list columns with the per-layer engagement (format version ≥ 2).
LAYER_COLUMNS: tuple[str, str] = ("interval_counts", "intervals_rad")


def _stat_column(name: str) -> str:
    unit = "nm" if name.startswith("torque") else "n"
    return f"{name}_{unit}"


#: Predicted-state columns derived from :data:`millsense.plan.predict.STAT_NAMES`.
STAT_COLUMNS: tuple[str, ...] = tuple(_stat_column(n) for n in STAT_NAMES)

#: Every column of a plan, in file order.
COLUMNS: tuple[str, ...] = (
    "s_mm",
    "t_s",
    "x_mm",
    "y_mm",
    "z_mm",
    "a_deg",
    "c_deg",
    "feed_mm_min",
    "spindle_rpm",
    "tool",
    "nc_line",
    "source_line",
    "rapid",
    "in_cut",
    "axial_depth_mm",
    "entry_deg",
    "exit_deg",
    "n_intervals",
    "gain_cwe_mm",
    "engaged_area_mm2",
    "feed_angle_deg",
    "ktc_n_mm2",
    "chip_load_mm",
    "mrr_cm3_min",
    "power_w",
    "fres_avg_n",
    *STAT_COLUMNS,
)
_INT_COLUMNS = frozenset({"tool", "nc_line", "source_line", "n_intervals"})
_BOOL_COLUMNS = frozenset({"rapid", "in_cut"})
#: The columns the look-ahead reads (:meth:`VirtualPlan.look_ahead`).
_LOOK_COLUMNS = ("t_s", "in_cut", "engaged_area_mm2", "chip_load_mm")
#: Those columns of a column mapping, as a tuple (one C call per look-ahead).
_look_columns_of = itemgetter(*_LOOK_COLUMNS)


@dataclass(frozen=True)
class LookAhead:
    """Look-ahead verdict over the next horizon (seed 000 §2.10).

    Attributes
    ----------
    flag : int
        2 if leaving the cut or entering a cavity (hold the feed), else 1 if engagement or
        chip load rises by ≥ 15 % (feed-forward the predicted force), else 0.
    rising, leaving_cut, entering_cavity : bool
        The individual conditions.
    event_row : int
        First row where the flagged condition occurs (−1 if none).
    time_to_event_s : float
        Time until that row at the given feed override [s] (inf if none).
    last_row : int
        Last row inside the horizon.
    """

    flag: int
    rising: bool
    leaving_cut: bool
    entering_cavity: bool
    event_row: int
    time_to_event_s: float
    last_row: int


@dataclass
class LayerIntervals:
    """Per-step, per-layer immersion intervals of a plan (the CWE of every row).

    Attributes
    ----------
    counts : (n, L) int16
        Intervals per step and layer (layers split the row's axial depth, tip upwards).
    intervals_rad : (n, L, M, 2) float32
        (entry, exit) [rad] in the tool feed frame; rows beyond ``counts`` are zero.
    """

    counts: NDArray[np.int16]
    intervals_rad: NDArray[np.float32]

    def __post_init__(self) -> None:
        c = np.asarray(self.counts)
        iv = np.asarray(self.intervals_rad)
        if c.ndim != 2 or iv.ndim != 4 or iv.shape[:2] != c.shape or iv.shape[3] != 2:
            raise InputDataError(
                f"plan: layer intervals of shape {iv.shape} do not fit counts {c.shape}"
            )
        if c.size and (int(c.min()) < 0 or int(c.max()) > iv.shape[2]):
            raise InputDataError("plan: interval counts outside 0..M")

    def __len__(self) -> int:
        return int(self.counts.shape[0])

    @property
    def n_layers(self) -> int:
        """Number of layers L."""
        return int(self.counts.shape[1])

    @classmethod
    def from_engagement(cls, eng: EngagementResult) -> LayerIntervals:
        """The intervals of an :class:`~millsense.plan.cwe.EngagementResult` (copied)."""
        iv = eng.intervals_rad.astype(np.float32, copy=True)
        m = iv.shape[2]
        iv[np.arange(m)[None, None, :] >= eng.n_intervals[:, :, None]] = 0.0
        return cls(eng.n_intervals.astype(np.int16, copy=True), iv)

    def flat(self) -> tuple[NDArray[np.int32], NDArray[np.float32]]:
        """Offsets (n + 1,) into the flattened values and the values (2 Σ counts,) float32.

        Row k holds ``values[offsets[k]:offsets[k+1]]`` = (entry, exit) of every valid
        interval, layer by layer (tip upwards), interval order kept.
        """
        m = self.intervals_rad.shape[2]
        valid = np.arange(m)[None, None, :] < self.counts[:, :, None]
        values = self.intervals_rad[valid].reshape(-1)  # C order: row, layer, interval
        per_row = 2 * self.counts.sum(axis=1, dtype=np.int64)
        offsets = np.concatenate([[0], np.cumsum(per_row)]).astype(np.int32)
        return offsets, np.ascontiguousarray(values, dtype=np.float32)

    @classmethod
    def from_flat(
        cls, counts: NDArray[Any], offsets: NDArray[Any], values: NDArray[Any], where: str
    ) -> LayerIntervals:
        """Inverse of :meth:`flat` (``counts`` (n, L)); InputDataError if inconsistent."""
        c = np.asarray(counts, dtype=np.int64)
        off = np.asarray(offsets, dtype=np.int64)
        v = np.asarray(values, dtype=np.float32)
        n, n_layers = c.shape
        if c.size and c.min() < 0:
            raise InputDataError(f"{where}: negative interval count")
        if off.shape != (n + 1,) or not np.array_equal(np.diff(off), 2 * c.sum(axis=1)):
            raise InputDataError(f"{where}: 'intervals_rad' lengths differ from 'interval_counts'")
        m = max(int(c.max()) if c.size else 0, 1)
        iv = np.zeros((n, n_layers, m, 2), dtype=np.float32)
        flat_c = c.reshape(-1)
        total = int(flat_c.sum())
        group = np.repeat(np.arange(n * n_layers), flat_c)
        first = np.concatenate([[0], np.cumsum(flat_c)[:-1]])
        pos = np.arange(total) - first[group]
        pairs = v[int(off[0]) : int(off[0]) + 2 * total].reshape(-1, 2)
        iv[group // n_layers, group % n_layers, pos] = pairs
        return cls(c.astype(np.int16), iv)


@dataclass
class VirtualPlan:
    """One row per path step; columns of :data:`COLUMNS` (field units in the names).

    Attributes
    ----------
    columns : dict of str to (n,) array
        The table.
    metadata : dict
        Program, tool, material, stock, step, software version, notes (JSON-serialisable).
    basis : ForceBasis, optional
        Force series per engagement signature (in memory only; lets the scheduler and the
        calibration recompute peaks exactly). ``None`` for a plan read from a file.
    layers : LayerIntervals, optional
        Full per-layer engagement of every row (format version 2); ``None`` for a version-1
        file (only the widest interval is known then).
    """

    columns: dict[str, NDArray[Any]]
    metadata: dict[str, Any] = field(default_factory=dict)
    basis: ForceBasis | None = None
    layers: LayerIntervals | None = None
    #: the x, y, z columns :meth:`match` searched last and their contiguous copies in metres
    _match_xyz: tuple[tuple[Any, ...], tuple[FloatArray, ...]] | None = field(
        default=None, init=False, repr=False, compare=False
    )
    #: the columns :meth:`look_ahead` read last and their float64 copies
    _look_cols: tuple[tuple[Any, ...], tuple[FloatArray, ...]] | None = field(
        default=None, init=False, repr=False, compare=False
    )

    def __post_init__(self) -> None:
        missing = [c for c in COLUMNS if c not in self.columns]
        if missing:
            raise InputDataError(f"plan: missing column {missing[0]!r}")
        n = {int(np.shape(v)[0]) for v in self.columns.values()}
        if len(n) != 1:
            raise InputDataError("plan: columns differ in length")
        if self.layers is not None and len(self.layers) != n.pop():
            raise InputDataError("plan: layer intervals differ in length from the columns")

    def __len__(self) -> int:
        return int(self.columns["x_mm"].shape[0])

    def __getitem__(self, name: str) -> NDArray[Any]:
        return self.columns[name]

    @property
    def xyz_m(self) -> FloatArray:
        """(n, 3) tool-tip positions [m]."""
        return np.column_stack([self.columns[c] * MM for c in ("x_mm", "y_mm", "z_mm")])

    # ------------------------------------------------------------------ files

    def write(self, path: str | os.PathLike[str]) -> Path:
        """Write the plan as Parquet, atomically (temporary file in the same folder + rename).

        After a failure no file (and no partial file) is left at ``path``.
        """
        import pyarrow as pa
        import pyarrow.parquet as pq

        p = Path(path)
        md = dict(self.metadata)
        md["format"] = "millsense-plan"
        md["format_version"] = PLAN_FORMAT_VERSION if self.layers is not None else 1
        meta = {META_KEY: json.dumps(md, default=str).encode()}
        arrays = [pa.array(np.asarray(self.columns[c])) for c in COLUMNS]
        names = list(COLUMNS)
        if self.layers is not None:
            lay = self.layers
            n, n_layers = lay.counts.shape
            c_off = np.arange(n + 1, dtype=np.int32) * n_layers
            counts = pa.ListArray.from_arrays(
                pa.array(c_off), pa.array(lay.counts.reshape(-1).astype(np.int16))
            )
            off, vals = lay.flat()
            ivs = pa.ListArray.from_arrays(pa.array(off), pa.array(vals, type=pa.float32()))
            arrays += [counts, ivs]
            names += list(LAYER_COLUMNS)
        table = pa.Table.from_arrays(arrays, names=names).replace_schema_metadata(meta)
        tmp = p.with_name(f".{p.name}.{os.getpid()}.tmp")
        try:
            with open(tmp, "wb") as fh:
                pq.write_table(table, fh, compression="zstd")
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, p)
        except BaseException:
            with contextlib.suppress(OSError):
                tmp.unlink()
            raise
        return p

    @classmethod
    def read(cls, path: str | os.PathLike[str]) -> VirtualPlan:
        """Read a plan written by :meth:`write` (one-line InputDataError if it is not one)."""
        import pyarrow as pa

        from millsense.core.parquet_read import read_parquet_table

        p = Path(path)
        try:
            table = read_parquet_table(p)
        except FileNotFoundError:
            raise InputDataError(f"{p}: no such file") from None
        except (pa.ArrowInvalid, OSError) as exc:
            first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
            raise InputDataError(f"{p}: not a Parquet file ({first})") from None
        names = set(table.column_names)
        for c in COLUMNS:
            if c not in names:
                raise InputDataError(f"{p}: not a millsense plan (missing column {c!r})")
        raw = (table.schema.metadata or {}).get(META_KEY, b"{}")
        try:
            meta = json.loads(raw)
        except json.JSONDecodeError:
            raise InputDataError(f"{p}: plan metadata is not valid JSON") from None
        if not isinstance(meta, dict):
            raise InputDataError(f"{p}: plan metadata is not a JSON object")
        version = meta.get("format_version", 1)
        if (
            isinstance(version, bool)
            or not isinstance(version, int)
            or not (1 <= version <= PLAN_FORMAT_VERSION)
        ):
            raise InputDataError(
                f"{p}: plan format version {version!r} is not supported "
                f"(this millsense reads 1 to {PLAN_FORMAT_VERSION})"
            )
        cols = {c: table.column(c).to_numpy() for c in COLUMNS}
        layers = None
        if version >= 2:
            for c in LAYER_COLUMNS:
                if c not in names:
                    raise InputDataError(f"{p}: plan version {version} misses column {c!r}")
            layers = _read_layers(table, p)
        return cls(cols, meta, layers=layers)

    # ------------------------------------------------------------------ queries

    def match(
        self,
        tcp_xyz_m: FloatArray,
        from_row: int = 0,
        tol_m: float = MATCH_TOLERANCE_M,
        max_ahead: int = 5000,
    ) -> IntArray:
        """Rows of measured tool-centre positions, searching forward from the last match.

        Parameters
        ----------
        tcp_xyz_m : (m, 3) or (3,) float
            Measured TCP positions [m] in time order (e.g. one batch of 333 Hz samples).
        from_row : int
            Row to start from (the last match of the previous batch).
        tol_m : float
            Tolerance per axis [m] (±10 µm, seed 000 C15).
        max_ahead : int
            Rows searched beyond the last match (bounds the work when off the path).

        Returns
        -------
        (m,) int
            Matched row per sample, −1 where none (the search then continues from the last
            match).

        Notes
        -----
        Rows are points every step (0.4 mm); at 333 Hz a TCP at 400 mm/min moves 20 µm per
        sample, so it rarely lies within ±10 µm of a row point itself. A sample therefore
        matches the first polyline segment [r, r+1] at or after the last match whose closest
        point is within the tolerance on every axis; its row is r (the state the tool is in
        while travelling from r to r+1), or r+1 at the segment's end. Compiled loop over
        samples and rows.
        """
        p = np.asarray(tcp_xyz_m, dtype=float)
        if p.ndim < 2:  # (3,) → (1, 3), as np.atleast_2d gives it (without its Python layer)
            p = p.reshape(1, -1)
        if p.shape[1] != 3:
            raise InputDataError(f"plan: tcp_xyz_m must be (m, 3), got {p.shape}")
        if not (0 <= from_row < len(self)):
            raise InputDataError(f"plan: from_row {from_row} outside 0..{len(self) - 1}")
        out = np.empty(p.shape[0], dtype=np.int64)
        columns = self.columns
        cols = (columns["x_mm"], columns["y_mm"], columns["z_mm"])
        known = self._match_xyz
        if (
            known is None
            or known[0][0] is not cols[0]
            or known[0][1] is not cols[1]
            or known[0][2] is not cols[2]
        ):
            # once per plan, not per call (a chunk's matches are a few samples; the plan may
            # have 10⁵ rows)
            xyz = self.xyz_m
            known = (cols, tuple(np.ascontiguousarray(xyz[:, i]) for i in range(3)))
            self._match_xyz = known
        px, py, pz = known[1]
        _k.match_rows(
            np.ascontiguousarray(p[:, 0]),
            np.ascontiguousarray(p[:, 1]),
            np.ascontiguousarray(p[:, 2]),
            px,
            py,
            pz,
            int(from_row),
            float(tol_m),
            int(max_ahead),
            out,
        )
        return out

    def look_ahead(
        self,
        row: int,
        horizon_s: float = LOOK_AHEAD_S,
        feed_override: float = 1.0,
        rise: float = RISE_FRACTION,
    ) -> LookAhead:
        """Flags for the path over the next ``horizon_s`` at the current feed override.

        Parameters
        ----------
        row : int
            Current row (from :meth:`match`).
        horizon_s : float
            Look-ahead time [s] (0.5 s in seed 000 §2.10).
        feed_override : float
            Current feed override (1 = programmed); the horizon covers programmed time
            horizon × override.
        rise : float
            Relative rise of engaged area or chip load that sets flag 1 (0.15).

        Returns
        -------
        LookAhead

        Notes
        -----
        Decision (docs/decisions/0063-virtual-plan-look-ahead-seed-000-2-10.md): with A the engaged
        area and c the chip load of the current row, *rising* is a later row in cut with
        A ≥ (1 + rise) A₀ or c ≥ (1 + rise) c₀, or any row in cut when the current row is
        not; *leaving the cut*: in cut now and the rows from some point to the horizon are
        all out of cut; *entering a cavity*: in cut now and, before the cut resumes within
        the horizon, a row out of cut or with A ≤ (1 − rise) A₀.
        """
        n = len(self)
        if not (0 <= row < n):
            raise InputDataError(f"plan: row {row} outside 0..{n - 1}")
        if not (horizon_s >= 0 and feed_override > 0):
            raise InputDataError("plan: horizon_s must be ≥ 0 and feed_override > 0")
        t, cut, area, chip = self._look_columns()
        flag, rising, leaving, cavity, event, end = _k.look_ahead_flags(
            t, cut, area, chip, int(row), float(horizon_s * feed_override), float(rise)
        )
        dt = (t[event] - t[row]) / feed_override if event >= 0 else math.inf
        return LookAhead(int(flag), bool(rising), bool(leaving), bool(cavity), int(event),
                         float(dt), int(end) - 1)  # fmt: skip

    def _look_columns(self) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """The columns :meth:`look_ahead` reads, as contiguous float64 arrays, converted once
        per plan (the verdict runs every revolution; the plan may have 10⁵ rows)."""
        cols = _look_columns_of(self.columns)
        # (the same arrays as last time: compared by identity, in C)
        if self._look_cols is None or not all(map(is_, self._look_cols[0], cols)):
            conv = tuple(np.ascontiguousarray(c, dtype=np.float64) for c in cols)
            self._look_cols = (cols, conv)
        t, cut, area, chip = self._look_cols[1]
        return t, cut, area, chip


def _read_layers(table: Any, p: Path) -> LayerIntervals:
    """The layer columns of a version-2 table (InputDataError naming the file if malformed)."""
    import pyarrow as pa

    try:
        cnt = table.column(LAYER_COLUMNS[0]).combine_chunks()
        ivs = table.column(LAYER_COLUMNS[1]).combine_chunks()
        if not (pa.types.is_list(cnt.type) and pa.types.is_list(ivs.type)):
            raise TypeError("not list columns")
        c_off = np.asarray(cnt.offsets.to_numpy(), dtype=np.int64)
        c_val = np.asarray(cnt.values.to_numpy(zero_copy_only=False), dtype=np.int64)
        i_off = np.asarray(ivs.offsets.to_numpy(), dtype=np.int64)
        i_val = np.asarray(ivs.values.to_numpy(zero_copy_only=False), dtype=np.float32)
    except (TypeError, ValueError, pa.ArrowException) as exc:
        raise InputDataError(f"{p}: plan layer columns are malformed ({exc})") from None
    n = table.num_rows
    per_row = np.diff(c_off)
    n_layers = int(per_row[0]) if n else 0
    if n and (n_layers < 1 or np.any(per_row != n_layers)):
        raise InputDataError(f"{p}: 'interval_counts' must hold the same number of layers per row")
    counts = c_val[int(c_off[0]) : int(c_off[0]) + n * n_layers].reshape(n, n_layers)
    return LayerIntervals.from_flat(counts, i_off, i_val, str(p))


def tool_from_metadata(meta: Mapping[str, Any], where: str = "plan") -> EndMill:
    """The :class:`EndMill` stored in a plan's metadata (``tool``: diameter, flutes, helix,
    pitch, shape, runout); one-line InputDataError naming the missing key."""
    t = meta.get("tool")
    if not isinstance(t, Mapping):
        raise InputDataError(f"{where}: metadata key 'tool' missing (plan written before v2?)")
    try:
        pitch = t.get("pitch_deg")
        return EndMill(
            diameter_m=float(t["diameter_mm"]) * MM,
            n_flutes=int(t["flutes"]),
            pitch_angles_rad=None if pitch is None else tuple(math.radians(v) for v in pitch),
            helix_rad=math.radians(float(t.get("helix_deg", 0.0))),
            shape=t.get("shape", "flat"),
            runout_offset_m=float(t.get("runout_um", 0.0)) * UM,
            runout_angle_rad=math.radians(float(t.get("runout_angle_deg", 0.0))),
        )
    except KeyError as exc:
        raise InputDataError(f"{where}: metadata key 'tool.{exc.args[0]}' missing") from None
    except (TypeError, ValueError) as exc:
        raise InputDataError(f"{where}: metadata 'tool' is invalid ({exc})") from None


def coefficients_from_metadata(meta: Mapping[str, Any], where: str = "plan") -> CuttingCoefficients:
    """The cutting coefficients stored in a plan's metadata (``material``, N/mm² and N/mm),
    the calibrated K_tc if the plan was calibrated (K_rc, K_ac scaled with it)."""
    m = meta.get("material")
    if not isinstance(m, Mapping):
        raise InputDataError(f"{where}: metadata key 'material' missing")
    try:
        ktc = float(m["ktc_n_mm2"])
        scale = float(meta.get("ktc_calibrated_n_mm2", ktc)) / ktc if ktc > 0 else 1.0
        return CuttingCoefficients(
            ktc=ktc * scale * 1e6,
            krc=float(m["krc_n_mm2"]) * scale * 1e6,
            kac=float(m["kac_n_mm2"]) * scale * 1e6,
            kte=float(m["kte_n_mm"]) * 1e3,
            kre=float(m["kre_n_mm"]) * 1e3,
            kae=float(m["kae_n_mm"]) * 1e3,
        )
    except KeyError as exc:
        raise InputDataError(f"{where}: metadata key 'material.{exc.args[0]}' missing") from None
    except (TypeError, ValueError) as exc:
        raise InputDataError(f"{where}: metadata 'material' is invalid ({exc})") from None


# ---------------------------------------------------------------------------- building


def _single_tool(sp: SampledPath, source: str) -> None:
    tools = np.unique(sp.tool[sp.tool != 0])
    if tools.size > 1:
        k = int(np.flatnonzero((sp.tool != 0) & (sp.tool != sp.tool[sp.tool != 0][0]))[0])
        raise ProgramError(
            f"{source}:{int(sp.source_line[k])}: tool change to T{int(sp.tool[k])}; "
            "a plan covers one tool (split the program at tool changes)"
        )


def _check_cutting_states(sp: SampledPath, eng: EngagementResult, source: str) -> None:
    bad = eng.in_cut & ~sp.rapid & (sp.spindle_speed <= 0)
    if bad.any():
        k = int(np.argmax(bad))
        raise ProgramError(
            f"{source}:{int(sp.source_line[k])}: the tool is in material with the spindle stopped"
        )
    ccw = eng.in_cut & ~sp.rapid & (sp.spindle_dir < 0)
    if ccw.any():
        k = int(np.argmax(ccw))
        raise ProgramError(
            f"{source}:{int(sp.source_line[k])}: cutting with M4 (counter-clockwise) is not "
            "supported by the engagement model"
        )


def _widest(eng: EngagementResult) -> tuple[FloatArray, FloatArray, IntArray]:
    """Entry/exit [rad] of the widest interval over all layers, max interval count."""
    iv = eng.intervals_rad.astype(np.float64)
    m = iv.shape[2]
    valid = np.arange(m)[None, None, :] < eng.n_intervals[:, :, None]
    width = np.where(valid, iv[..., 1] - iv[..., 0], -1.0).reshape(len(eng), -1)
    best = np.argmax(width, axis=1)
    flat = iv.reshape(len(eng), -1, 2)
    pick = flat[np.arange(len(eng)), best]
    ok = width[np.arange(len(eng)), best] >= 0
    entry = np.where(ok, pick[:, 0], 0.0)
    exit_ = np.where(ok, pick[:, 1], 0.0)
    return entry, exit_, eng.n_intervals.max(axis=1).astype(np.int64)


def _next_motion_directions(sp: SampledPath) -> NDArray[np.float64]:
    """Direction of the motion that follows each step, P_{k+1} − P_k (unit-free).

    The engagement of step k is the material the edges meet on the way from P_k to P_{k+1}
    (docs/decisions/0042-z-map-engagement-criterion.md,
    docs/decisions/0066-engagement-faces-the-next-motion.md), so its front half must face that
    motion. The incoming tangent differs at the last step of a move: at a corner it faces the wall
    the previous move ran into, which the tool never cuts, and read it as engaged (false peaks at
    pocket wall ends; decision "Engagement faces the next motion"). The last step of the path keeps
    its tangent.
    """
    xyz = np.column_stack([sp.x, sp.y, sp.z])
    d = np.empty_like(xyz)
    d[:-1] = np.diff(xyz, axis=0)
    d[-1] = sp.tangent[-1]
    still = np.hypot(d[:, 0], d[:, 1]) < 1e-12
    d[still] = sp.tangent[still]  # plunges keep their tangent (cwe keeps the last XY heading)
    return d


def _across_axis(tangent: NDArray[np.float64]) -> NDArray[np.float64]:
    """Fraction of the feed across the tool axis at each step, |t_xy|/|t| of the tangent of the
    move the step lies on (decision 1673; not the chord to the next step, which at a corner
    mixes two moves: the last step of a slot before a retract would lose its chip).

    The peripheral flutes cut a chip of the feed per tooth across the tool axis (the force
    model, :mod:`millsense.process.forces`, and the virtual machine's process, which takes the
    tool-centre speed across the axis): on a ramp the feed along the axis is cut by the end
    face, which neither model represents (:mod:`millsense.plan.cwe`: material below the tool
    tip is not represented). A plunge (no XY part) cuts no peripheral chip; a ramp of angle α
    a chip of cos α of the feed per tooth. The tool axis is the part's z, as in the engagement
    (:mod:`millsense.plan.cwe`)."""
    norm = np.linalg.norm(tangent, axis=1)
    xy = np.hypot(tangent[:, 0], tangent[:, 1])
    return np.where(norm > 0, xy / np.where(norm > 0, norm, 1.0), 1.0)


def _clear_axial_retracts(sp: SampledPath, eng: EngagementResult) -> None:
    """No engagement at a step whose next motion is along the tool axis, upwards (a retract
    out of a pocket or slot; decision 1544).

    The engagement of a step faces the next motion (decision 0066); a motion without an XY part
    keeps the last XY heading, which at the end of a cut faces the wall the tool stopped at.
    Moving up along its axis a flat or ball end mill leaves that wall and cuts nothing, while
    the wall's edge cells, within the tool's circle to the z-map's resolution, read as a
    half-slot all the way up (a straight G0 retract from a 3 mm slot: seven steps "in
    material"). Plunges (downwards) keep their engagement."""
    xyz = np.column_stack([sp.x, sp.y, sp.z])
    d = np.diff(xyz, axis=0)
    up = np.zeros(len(sp), dtype=bool)
    up[:-1] = (np.hypot(d[:, 0], d[:, 1]) < 1e-12) & (d[:, 2] > 0)
    if up.any():
        eng.axial_depth_m[up] = 0.0
        eng.n_intervals[up] = 0
        eng.gain_cwe_m[up] = 0.0
        eng.engaged_area_m2[up] = 0.0
        eng.contact_area_m2[up] = 0.0


def plan_program(
    program: Toolpath,
    stock: ZMapStock,
    tool: EndMill,
    coeffs: CuttingCoefficients,
    *,
    step_m: float = DEFAULT_STEP,
    n_layers: int = 10,
    angles_per_rev: int = 720,
    chunk_steps: int = 20_000,
    progress: Callable[[int, int], None] | None = None,
    metadata: Mapping[str, Any] | None = None,
) -> VirtualPlan:
    """Sample a program, cut the stock, predict process states: the virtual plan.

    Parameters
    ----------
    program : Toolpath
        From :func:`millsense.plan.gcode.interpret_file` (one tool).
    stock : ZMapStock
        Raw stock (cut in place; it ends as the finished part).
    tool : EndMill
        The tool (clockwise spindle).
    coeffs : CuttingCoefficients
        Cutting coefficients of the material [N/m², N/m].
    step_m : float
        Path step [m] (0.4 mm, seed 000).
    n_layers : int
        Engagement layers.
    angles_per_rev : int
        Spindle angles per revolution for the force statistics.
    chunk_steps : int
        Steps per engagement call (granularity of ``progress``).
    progress : callable, optional
        ``progress(done, total)`` in steps, after each chunk and at the end.
    metadata : mapping, optional
        Extra metadata stored with the plan (program, tool, material, stock names...).

    Returns
    -------
    VirtualPlan
        With its in-memory :class:`~millsense.plan.predict.ForceBasis`.

    Raises
    ------
    ProgramError
        Several tools, or a feed move in material with the spindle stopped or in M4.
    """
    from millsense import __version__

    sp = sample_path(program, step_m)
    n = len(sp)
    if n == 0:
        raise ProgramError(f"{program.source}: program has no motion to plan")
    _single_tool(sp, program.source)
    motion = _next_motion_directions(sp)
    parts: list[EngagementResult] = []
    prev: tuple[float, float, float] | None = None
    total = n + max(n // 10, 1)  # the force prediction counts as a tenth of the work
    for lo in range(0, n, chunk_steps):
        hi = min(lo + chunk_steps, n)
        parts.append(
            compute_engagement(
                stock,
                tool,
                sp.x[lo:hi],
                sp.y[lo:hi],
                sp.z[lo:hi],
                motion[lo:hi],
                previous_xyz_m=prev,
                n_layers=n_layers,
            )
        )
        prev = (float(sp.x[hi - 1]), float(sp.y[hi - 1]), float(sp.z[hi - 1]))
        if progress is not None:
            progress(hi, total)
    eng = EngagementResult.concatenate(parts)
    _clear_axial_retracts(sp, eng)
    _check_cutting_states(sp, eng, program.source)
    omega = np.where(sp.spindle_dir != 0, sp.spindle_speed, 0.0)
    # the flutes' chip comes from the feed across the tool axis (decision 1673)
    pred = predict_states(
        eng, coeffs, sp.feed * _across_axis(sp.tangent), omega, active=~sp.rapid,
        angles_per_rev=angles_per_rev,
    )  # fmt: skip
    if progress is not None:
        progress(total, total)
    entry, exit_, niv = _widest(eng)
    act = pred.active
    cols: dict[str, NDArray[Any]] = {
        "s_mm": sp.s / MM,
        "t_s": sp.t,
        "x_mm": sp.x / MM,
        "y_mm": sp.y / MM,
        "z_mm": sp.z / MM,
        "a_deg": np.degrees(sp.a),
        "c_deg": np.degrees(sp.c),
        "feed_mm_min": sp.feed / MM_PER_MIN,
        "spindle_rpm": omega / RPM,
        "tool": sp.tool.astype(np.int64),
        "nc_line": sp.nc_line.astype(np.int64),
        "source_line": sp.source_line.astype(np.int64),
        "rapid": sp.rapid.astype(bool),
        "in_cut": eng.in_cut.astype(bool),
        "axial_depth_mm": eng.axial_depth_m / MM,
        "entry_deg": np.degrees(entry),
        "exit_deg": np.degrees(exit_),
        "n_intervals": niv,
        "gain_cwe_mm": eng.gain_cwe_mm,
        "engaged_area_mm2": eng.engaged_area_m2 / MM**2,
        "feed_angle_deg": np.degrees(eng.feed_angle_rad),
        "ktc_n_mm2": np.where(act, coeffs.ktc / 1e6, 0.0),
        "chip_load_mm": pred.chip_load_m / MM,
        "mrr_cm3_min": pred.mrr_m3_s * 1e6 * 60.0,
        "power_w": pred.power_w,
        "fres_avg_n": pred.fres_avg_n,
    }
    for name, col in zip(STAT_NAMES, STAT_COLUMNS, strict=True):
        cols[col] = pred.stats[name]
    # a rapid through material is a warning of the plan's checks (plan.checks.check_plan)
    notes = list(program.notes)
    meta: dict[str, Any] = {
        "program": program.source,
        "tool": {
            "diameter_mm": tool.diameter_m / MM,
            "flutes": tool.n_flutes,
            "helix_deg": math.degrees(tool.helix_rad),
            "shape": tool.shape,
            "pitch_deg": (
                None
                if tool.pitch_angles_rad is None
                else [math.degrees(v) for v in tool.pitch_angles_rad]
            ),
            "runout_um": tool.runout_offset_m / UM,
            "runout_angle_deg": math.degrees(tool.runout_angle_rad),
        },
        "material": {
            "ktc_n_mm2": coeffs.ktc / 1e6,
            "krc_n_mm2": coeffs.krc / 1e6,
            "kac_n_mm2": coeffs.kac / 1e6,
            "kte_n_mm": coeffs.kte / 1e3,
            "kre_n_mm": coeffs.kre / 1e3,
            "kae_n_mm": coeffs.kae / 1e3,
        },
        "stock": {
            "x0_mm": stock.x0_m / MM,
            "y0_mm": stock.y0_m / MM,
            "bottom_mm": stock.bottom_m / MM,
            "resolution_mm": stock.resolution_m / MM,
            "cells": [stock.nx, stock.ny],
        },
        "step_mm": step_m / MM,
        "n_layers": n_layers,
        "n_discs": 2 * n_layers,  # predict_states' default disc count
        "angles_per_rev": angles_per_rev,
        "period_deg": math.degrees(pred.basis.period_rad),
        "signatures": pred.basis.n_signatures,
        "software": f"millsense {__version__}",
        "notes": notes,
    }
    if metadata:
        meta.update(dict(metadata))
    return VirtualPlan(cols, meta, pred.basis, LayerIntervals.from_engagement(eng))
