"""A live source: one feed axis cutting a straight slot, with ground truth.

The foundation's thin machine simulation, used by ``millsense demo``: the X drive of a machine
preset (rigid body, Coulomb + viscous friction, cascade control, :mod:`.rigid_drive`) moves the
table at the programmed feed while a flat end mill cuts a full-immersion slot whose axial depth
follows a schedule (air, depth steps, air). The cutting force comes from the mechanistic model
(:func:`millsense.process.forces.milling_forces`) at the spindle angle of every sample.

Frames: the table moves along +X; the tool therefore feeds along −X relative to the workpiece.
The process model gives the force on the tool in its feed frame (x along the feed); the force
on the table along +X is then ``F_table,X = −F_tool·(+X) = F_tool,x_feed`` — negative in a
cut: it resists the motion, and the drive feels the load torque ``(r_g/η)·(−F_table,X)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from millsense.core.config import FeedAxisConfig, MaterialConfig, ToolConfig
from millsense.core.recording import ChannelInfo
from millsense.process.coefficients import CuttingCoefficients
from millsense.process.engagement import Engagement
from millsense.process.forces import milling_forces
from millsense.process.geometry import EndMill
from millsense.simulator.rigid_drive import RigidDriveParams, RigidDriveSim
from millsense.streaming.block import Chunk
from millsense.streaming.sources import Source


@dataclass(frozen=True)
class DepthSegment:
    """From ``start_s`` on, the axial depth of cut is ``depth_m`` (0 = air)."""

    start_s: float
    depth_m: float


class SlotCutSource(Source):
    """Simulated single-axis slot cut producing CNC channels and ``truth/`` channels.

    Channels (SI): ``x/current_cmd`` and ``x/current`` (A), ``x/motor_speed`` (rad/s, from
    the encoder), ``x/motor_angle`` (rad, encoder), ``x/position_cmd`` (m, interpolator),
    ``spindle/speed`` (rad/s); truth: ``truth/x/force`` (N, on the table along +X),
    ``truth/x/depth`` (m), ``truth/x/motor_speed`` (rad/s).
    """

    name = "simulated slot cut"

    def __init__(
        self,
        axis: FeedAxisConfig,
        tool: ToolConfig,
        material: MaterialConfig,
        *,
        spindle_rpm: float,
        feed_per_tooth_m: float,
        duration_s: float,
        depth_schedule: Sequence[DepthSegment],
        sample_rate_hz: float = 10000.0,
        accel_time_s: float = 0.1,
        n_discs: int = 10,
        seed: int = 0,
    ) -> None:
        self.sample_rate_hz = sample_rate_hz
        self.t0_s = 0.0
        self.axis = axis
        self.params = RigidDriveParams.from_config(axis)
        self.drive = RigidDriveSim(self.params, sample_rate_hz, seed=seed)
        self.tool = EndMill.from_config(tool)
        self.coeffs = CuttingCoefficients.from_config(material)
        self.spindle_rad_s = spindle_rpm * 2.0 * math.pi / 60.0
        self.feed_per_tooth_m = feed_per_tooth_m
        self.feed_m_s = feed_per_tooth_m * tool.flutes * self.spindle_rad_s / (2.0 * math.pi)
        self.accel_time_s = accel_time_s
        self.n_total = round(duration_s * sample_rate_hz)
        self.schedule = sorted(depth_schedule, key=lambda s: s.start_s)
        self.n_discs = n_discs
        self.engagement = Engagement.slot()
        self._pos = 0

    @property
    def channel_info(self) -> list[ChannelInfo]:
        return [
            ChannelInfo("x/current_cmd", "A", "X drive current command (CNC nominal current)"),
            ChannelInfo("x/current", "A", "X drive actual current"),
            ChannelInfo("x/motor_speed", "rad/s", "X motor speed from the encoder difference"),
            ChannelInfo("x/motor_angle", "rad", "X motor encoder angle"),
            ChannelInfo("x/position_cmd", "m", "X table position command of the interpolator"),
            ChannelInfo("spindle/speed", "rad/s", "spindle speed"),
            ChannelInfo("truth/x/force", "N", "true cutting force on the table along +X"),
            ChannelInfo("truth/x/depth", "m", "true axial depth of cut"),
            ChannelInfo("truth/x/motor_speed", "rad/s", "true X motor speed"),
        ]

    def depth_at(self, t: np.ndarray) -> np.ndarray:
        """Axial depth (m) at times ``t`` from the schedule."""
        depth = np.zeros_like(t)
        for seg in self.schedule:
            depth[t >= seg.start_s] = seg.depth_m
        return depth

    def reference(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Table position (m) and velocity (m/s) commands: ramp to the feed, then constant."""
        ta, v = self.accel_time_s, self.feed_m_s
        vel = np.where(t < ta, v * t / ta, v)
        pos = np.where(t < ta, 0.5 * v * t**2 / ta, 0.5 * v * ta + v * (t - ta))
        return pos, vel

    def table_force(self, t: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """Force on the table along +X (N) from the mechanistic model, per sample."""
        force = np.zeros_like(t)
        angle = self.spindle_rad_s * t
        for d in np.unique(depth):
            if d <= 0:
                continue
            sel = depth == d
            f = milling_forces(
                self.tool,
                self.coeffs,
                self.engagement,
                self.feed_per_tooth_m,
                float(d),
                angle[sel],
                n_discs=self.n_discs,
            )
            force[sel] = f.fx_n  # F_table,X = F_tool,x_feed (see module docstring)
        return force

    def read(self, max_samples: int) -> Chunk | None:
        if self._pos >= self.n_total:
            return None
        start, stop = self._pos, min(self.n_total, self._pos + max_samples)
        t = np.arange(start, stop) / self.sample_rate_hz
        depth = self.depth_at(t)
        force = self.table_force(t, depth)
        pos, vel = self.reference(t)
        rg = self.params.transmission
        out = self.drive.advance(pos / rg, vel / rg, self.params.load_torque(-force))
        data = {
            "x/current_cmd": out["current_cmd"],
            "x/current": out["current"],
            "x/motor_speed": out["speed"],
            "x/motor_angle": out["angle"],
            "x/position_cmd": pos,
            "spindle/speed": np.full(len(t), self.spindle_rad_s),
            "truth/x/force": force,
            "truth/x/depth": depth,
            "truth/x/motor_speed": out["true_speed"],
        }
        self._pos = stop
        return Chunk(start, self.sample_rate_hz, self.t0_s, data)
