"""The virtual machine's job of a virtual plan (``simulate --plan``, ``run``, the demo)."""

from __future__ import annotations

from typing import Any

import numpy as np


def plan_job(
    vp: Any,
    mcfg: Any,
    plan_name: str,
    *,
    tool: str | None = None,
    material: str | None = None,
    events: Any = (),
    modes: Any = None,
    wear_vb_m: float = 0.0,
) -> tuple[Any, Any, dict[str, Any], list[str]]:
    """The virtual machine's job and process of a virtual plan: its path, feed, spindle
    speed and NC lines, cutting with the engagement of every row; tool and coefficients from
    the plan unless ``tool``/``material`` (presets or TOML) are given. Returns the job, the
    process coupling, the recording metadata and notes (shared by ``simulate --plan`` and
    ``run``).

    ``wear_vb_m``: the tool's flank wear land VB [m]; the coefficients are the worn tool's of
    the truth model (:class:`~millsense.simulator.wear.FlankWearModel`, decision 2001)."""
    from millsense.core.config import MaterialConfig, ToolConfig
    from millsense.core.presets import load_preset
    from millsense.plan.plan_engagement import PlanEngagement, plan_path
    from millsense.plan.virtual_plan import coefficients_from_metadata, tool_from_metadata
    from millsense.process.coefficients import CuttingCoefficients
    from millsense.process.geometry import EndMill
    from millsense.simulator.machine import Job
    from millsense.simulator.process_coupling import ProcessCoupling

    five = mcfg.kinematics == "5-axis-trunnion-ac"
    if tool is not None:
        end_mill = EndMill.from_config(load_preset(ToolConfig, tool))
    else:
        end_mill = tool_from_metadata(vp.metadata, plan_name)
    if material is not None:
        coeffs = CuttingCoefficients.from_config(load_preset(MaterialConfig, material))
    else:
        coeffs = coefficients_from_metadata(vp.metadata, plan_name)
    if wear_vb_m > 0:
        from millsense.simulator.wear import FlankWearModel

        coeffs = FlankWearModel().coefficients(coeffs, wear_vb_m)
    pp = plan_path(vp, five_axis=five)
    job = Job(pp.path, pp.feed_m_s, pp.spindle_rad_s, pp.nc_line, pp.rapid)
    source = PlanEngagement(vp)
    n_discs = int(vp.metadata.get("n_discs", 10))
    cut_rows = np.flatnonzero(source.row_index >= 0)
    first_cut = float(source.row_s_m[cut_rows[0]]) if len(cut_rows) else None
    meta_extra: dict[str, Any] = {
        "plan": plan_name,
        "program": str(vp.metadata.get("program", "")),
        "tool": tool or str(vp.metadata.get("tool_name", "plan")),
        # the teeth `monitor` and `estimate` read when no plan or option gives them (decision
        # 1716): without them a 3- or 4-flute run was judged at a 2-flute tooth frequency
        "flutes": int(end_mill.n_flutes),
        "material": material or str(vp.metadata.get("material_name", "plan")),
        "engagement": source.summary(),
    }
    if vp.metadata.get("program_sha256"):
        meta_extra["program_sha256"] = str(vp.metadata["program_sha256"])
    meta_extra["truth_wear_vb_mm"] = wear_vb_m * 1e3
    if first_cut is not None:
        meta_extra["first_engagement_path_m"] = first_cut
    process = ProcessCoupling(
        end_mill,
        coeffs,
        source,
        events=list(events),
        n_discs=n_discs,
        modes=modes,
        sample_rate_hz=mcfg.sample_rate_hz,
    )
    return job, process, meta_extra, list(source.notes)
